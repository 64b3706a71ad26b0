"""What the tests share: makers of lab files, states and sessions (analytic or damaged), the
bad-input harness, the references they check against, and where the repository and the real
samples are. Test modules import them as ``helpers.<module>``."""

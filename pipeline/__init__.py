"""The `pipeline` CLI and the stage code that turns phantom sessions into trained models."""

from core import __version__  # noqa: F401  (one version for the package)

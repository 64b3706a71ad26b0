"""Evaluating trained runs: Table 2's metrics beside the no-learning references, the
data-scarcity curve, and the eval runner."""

"""An independent reference for the MSM's spring forces, shared by the MSM tests."""

from __future__ import annotations

import numpy as np

from sim.msm.msm import MSM


def forces_by_edge_loop(model: MSM, x: np.ndarray, f_ext: np.ndarray) -> np.ndarray:
    """Independent implementation: one spring at a time from the edge list."""
    p = model.params
    f = f_ext - p.k_fixed * (x - model.rest)
    for a, b in model.edges():
        rest = np.linalg.norm(model.rest[b] - model.rest[a])
        d = x[b] - x[a]
        length = np.linalg.norm(d)
        fs = p.k_between * (length - rest) * d / length
        f[a] += fs
        f[b] -= fs
    return f

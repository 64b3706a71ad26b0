"""Each element's share of each label of the interior, and so its modulus.

An element 5 mm across does not follow a 12 mm lump's surface: its modulus is the mean of
its silicones' (a Voigt average), each weighted by the share of ``SAMPLES**3`` points spread
evenly through the element that fall in it. Without an interior every element is the block's.
"""

from __future__ import annotations

import numpy as np

from data_schema.interior import Interior
from sim.solid.elasticity import Elasticity

SAMPLES = 3          # points per element along each axis


def label_shares(elasticity: Elasticity, interior: Interior | None, n_labels: int
                 ) -> np.ndarray:
    """(E, n_labels) each element's share of labels 0 .. n_labels - 1 (rows sum to 1)."""
    n = elasticity.n_elements
    if interior is None:
        out = np.zeros((n, n_labels))
        out[:, 0] = 1.0
        return out
    mesh = elasticity.mesh
    corners = mesh.p[:, mesh.t]                               # (3, 8, E)
    lo, hi = corners.min(axis=1), corners.max(axis=1)         # (3, E)
    u = (np.arange(SAMPLES) + 0.5) / SAMPLES
    grid = np.stack(np.meshgrid(u, u, u, indexing="ij"), -1).reshape(-1, 3)   # (S, 3)
    pts = lo.T[:, None, :] + grid[None] * (hi - lo).T[:, None, :]             # (E, S, 3)
    labels = interior.label_at(pts.reshape(-1, 3)).reshape(n, -1)
    labels = np.where(labels < 0, 0, labels)          # a sliver outside the volume: block
    return np.stack([(labels == k).mean(axis=1) for k in range(n_labels)], axis=1)

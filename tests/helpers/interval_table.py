"""An interval table whose radii are known, for the tests of what reads one."""

from __future__ import annotations

import numpy as np

from train.model.conformal import LEVELS, Bins, IntervalTable

NEAR, FAR, HALF = 1e-3, 1e-4, 0.25      # m, m, N: the known table's radii and half-width
EDGE = 0.01                             # m: near the tip's path below it


def known_table() -> IntervalTable:
    """Points within ``EDGE`` of the tip's path get ``NEAR``, the rest ``FAR``; the force
    +- ``HALF``; at every level."""
    q = len(LEVELS)
    points = Bins(((EDGE,), (), ()), np.stack([np.full((1, 1, q), NEAR), np.full((1, 1, q), FAR)]),
                  np.full((2, 1, 1, q), 100))
    force = Bins(((), ()), np.full((1, 1, q), HALF), np.full((1, 1, q), 100))
    return IntervalTable(points, force, presses=3, examples=50)

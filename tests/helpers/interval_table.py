"""An interval table whose radii are known, for the tests of what reads one (also in the plain
form a checkpoint of the first version holds), and calibration scores whose quantiles are
known."""

from __future__ import annotations

import numpy as np

from train.intervals.levels import LEVELS
from train.intervals.table import Bins, IntervalTable

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


def near_far(rng: np.random.Generator, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Scores (m,) |N(0, s)| with s = 1 mm within 10 mm of the tip's path and 0.1 mm beyond,
    and their features (m, 3) (distance, depth, height; the depth and height carry nothing)."""
    dist = rng.uniform(0, 0.04, m)
    sigma = np.where(dist < 0.01, 1e-3, 1e-4)
    feats = np.stack([dist, rng.uniform(1e-3, 2e-3, m), rng.uniform(0, 1e-3, m)], 1)
    return np.abs(rng.normal(0, sigma)), feats


def stored_table() -> dict:
    """An ``intervals`` entry of ``best.pt`` as the first version of the intervals wrote it,
    spelled out key by key: two distance bins (radius 1 mm within 10 mm of the tip's path,
    0.1 mm beyond, at every level but 0.99 beyond, which is unbounded: null), one depth and
    one height bin, the force +- 0.25 N."""
    q = 99                                                    # levels 0.01 .. 0.99
    return {"levels": [round(0.01 * i, 2) for i in range(1, 100)],
            "point_features": ["distance", "depth", "height"],
            "force_features": ["depth", "height"], "min_count": 30,
            "points": {"edges": [[0.01], [], []],
                       "width": [[[[1e-3] * q]], [[[1e-4] * (q - 1) + [None]]]],
                       "count": [[[[100] * q]], [[[100] * q]]]},
            "force": {"edges": [[], []], "width": [[[0.25] * q]], "count": [[[50] * q]]},
            "presses": 3, "examples": 50}

"""Runs of True in a 1-D mask: a gap, a loaded stretch, a quiet one."""

from __future__ import annotations

import numpy as np


def true_runs(missing: np.ndarray) -> list[tuple[int, int]]:
    """``(start, stop)`` index pairs (stop exclusive) of the True runs in a 1-D mask."""
    m = np.concatenate([[False], np.asarray(missing, bool), [False]])
    edges = np.flatnonzero(np.diff(m.astype(np.int8)))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))

"""Region of interest: the points a press can move, so the network runs on those alone.

A press moves the surface near the tip's path and leaves the far surface where it is. The
core is every point within ``radius`` of the segment from the tip's start to its end
(:func:`near_path`): its predictions are used, and the points outside it stay at rest. A
model whose layers read the press (tip offsets) runs on the region: the core plus the rings
its graph layers read around it (``hops`` steps along each point's k nearest neighbours, so
the core's points keep the neighbours they would have in the whole surface; :func:`region`),
and its force head pools over that region. The paper's network on a known scene needs only
the core (its heads run on the core's cached terms; :mod:`train.inference.predictor`). The report
(``benchmarks/speed_accuracy.py``) measures what a radius costs.
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.spatial import cKDTree

from train.intervals.features import path_distance
from train.model.knn import TIE, WIDEST, Points, ranked, tiebreak


def neighbour_table(points: np.ndarray, k: int) -> np.ndarray:
    """Each point's k nearest points (N, k) int64, itself included, nearest first (a 3-D
    tree, no N x N), as the network's own kNN chooses them: the tree's order where the k + 1
    nearest distances are all apart by more than ``TIE`` (relative), and elsewhere (ties: a
    grid) the tree's candidates ranked by :func:`train.model.knn.ranked`, which breaks a tie
    by the points' coordinates, not by their order, searching again with more where a tie
    crosses the k-th."""
    tree, n = cKDTree(points), len(points)
    want = min(k + 1, n)
    dist, cand = tree.query(points, k=want)
    dist, cand = dist.reshape(n, want), cand.reshape(n, want).astype(np.int64)
    table = cand[:, :k].copy()
    rows = np.flatnonzero((np.diff(dist, axis=1) <= TIE * dist[:, 1:]).any(axis=1))
    p = torch.from_numpy(np.ascontiguousarray(points, dtype=np.float32))
    flat = Points(p, tiebreak(p), n)
    while len(rows):
        found = torch.from_numpy(cand[rows].reshape(len(rows), 1, -1))
        idx, wide = ranked(found, torch.ones_like(found, dtype=torch.bool),
                           p[rows].unsqueeze(1), flat,
                           torch.zeros(len(rows), 1, 1, dtype=torch.long), k)
        table[rows] = idx[:, 0].numpy()
        if want >= min(n, WIDEST):
            break
        rows, want = rows[wide[:, 0].numpy()], min(4 * want, n, WIDEST)
        cand = np.zeros((n, want), np.int64)
        cand[rows] = tree.query(points[rows], k=want)[1].reshape(len(rows), want)
    return table


def segment_distance(points: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Distance (N,) of each point from the segment start-end (a point when they coincide)."""
    return path_distance(points, start, end)


def near_path(points: np.ndarray, start: np.ndarray, end: np.ndarray, radius: float,
              least: int) -> np.ndarray:
    """Indices of the points within ``radius`` of the tip's path, in order; at least
    ``least`` of them (the nearest: k + 1, so a graph on them exists)."""
    dist = segment_distance(points, start, end)
    core = np.flatnonzero(dist <= radius)
    if len(core) < least:
        core = np.sort(np.argpartition(dist, least - 1)[:least])
    return core


def region(points: np.ndarray, table: np.ndarray, start: np.ndarray, end: np.ndarray,
           radius: float, hops: int) -> tuple[np.ndarray, np.ndarray]:
    """(core, used): indices of the points within ``radius`` of the tip's path (at least
    k + 1, the nearest, so the graph exists), and of those plus ``hops`` rings of neighbours
    (``table``), the core first."""
    core = near_path(points, start, end, radius, table.shape[1] + 1)
    inside = np.zeros(len(points), dtype=bool)
    inside[core] = True
    ring = inside.copy()
    for _ in range(hops):
        ring[table[ring].ravel()] = True
    return core, np.concatenate([core, np.flatnonzero(ring & ~inside)])

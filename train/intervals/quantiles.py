"""The calibration's math: split-conformal quantiles, binned (Mondrian).

A score's quantile at level q over n calibration scores is their ``ceil((n + 1) q)``-th
smallest (the finite-sample correction: with n exchangeable scores, a new one falls at or
below it with probability at least q; infinite where ``ceil((n + 1) q) > n``).

The bins (a quantile per bin, so that a point beside the tip and one far from it get their
own radii) are by the press's features (:mod:`train.intervals.features`). Their edges are
the calibration's own quantiles (:data:`SPLITS`: of the distance its nearest tenth and
quartiles, medians of the other two), so every lab's and the MSM's scales fit. A point within
:data:`~train.model.normalise.TIP_POINT` of the tip's path is the tip's own (a lab's tip
marker: its error is a fraction of its neighbours') and has a distance bin of its own
(:data:`LEADS`), the quantiles being of the surface's points alone. A bin with fewer than
:data:`MIN_COUNT` scores (or an infinite quantile) at a level takes its parent's: the same
bins without the last feature, then without the one before too, then every score (resolved
once, when the table is made; each width records how many scores it stands on).
"""

from __future__ import annotations

import numpy as np

from train.intervals.levels import LEVELS
from train.model.normalise import TIP_POINT

MIN_COUNT = 30        # scores a bin needs before its own quantile is used
# the calibration quantiles that make each feature's bin edges: the distance from the tip's
# path in its nearest tenth and quarters (the error falls steeply over the nearest 20 mm), the
# press's depth and the tip's height in halves
SPLITS = {"distance": (0.1, 0.25, 0.5, 0.75), "depth": (0.5,), "height": (0.5,)}
# a feature's fixed first edge: below it a bin of its own (the tip's own point), the quantiles
# of the rest
LEADS = {"distance": TIP_POINT}

Binned = tuple[tuple[tuple[float, ...], ...], np.ndarray, np.ndarray]   # edges, width, count


def conformal_quantile(scores: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """The split-conformal quantile of ``scores`` (n,) at each of ``levels`` (Q,): the
    ``ceil((n + 1) q)``-th smallest score, infinite where that exceeds n."""
    s = np.sort(np.asarray(scores, dtype=np.float64))
    rank = np.ceil(np.round((len(s) + 1) * np.asarray(levels), 9)).astype(np.int64)
    out = np.full(len(rank), np.inf)
    ok = rank <= len(s)
    out[ok] = s[rank[ok] - 1]
    return out


def bin_edges(values: np.ndarray, splits: tuple[float, ...], lead: float | None = None
              ) -> tuple[float, ...]:
    """A feature's bin edges: ``values``' quantiles at ``splits`` (duplicates dropped); with
    ``lead``, that edge first and the quantiles of the values at or above it (where any are)."""
    if lead is None:
        return tuple(float(v) for v in np.unique(np.quantile(values, splits)))
    rest = values[values >= lead]
    above = np.unique(np.quantile(rest, splits)) if len(rest) else np.empty(0)
    return (float(lead), *(float(v) for v in above[above > lead]))


def binned_quantiles(scores: np.ndarray, features: np.ndarray,
                     splits: tuple[tuple[float, ...], ...],
                     lead: tuple[float | None, ...] | None = None) -> Binned:
    """Per bin and level of :data:`LEVELS`, the quantile of scores (M,) whose features
    (M, K) fall in it, each feature binned at its calibration quantiles ``splits[k]`` (with
    ``lead[k]`` a value, the values below it a bin of their own, :func:`bin_edges`): the
    edges (bin i of a feature holds values in [edge i-1, edge i)), the widths
    (*shape, Q) (inf where nothing bounds them) and the scores each stands on (*shape, Q).
    A bin short of :data:`MIN_COUNT` scores (or unbounded at a level) takes its parent's
    (the last feature dropped first); a bin's widths never shrink as the level rises (a
    parent's quantile at a higher level may lie below the bin's own at a lower one: the bin
    keeps the wider), so its intervals nest."""
    lead = lead or (None,) * len(splits)
    edges = tuple(bin_edges(features[:, k], s, a)
                  for k, (s, a) in enumerate(zip(splits, lead, strict=True)))
    idx = np.stack([np.searchsorted(e, features[:, k], side="right")
                    for k, e in enumerate(edges)], 1)
    shape = tuple(len(e) + 1 for e in edges)
    levels = np.asarray(LEVELS)
    nodes = _node_quantiles(scores, idx, shape, levels)
    empty = (np.full(len(levels), np.inf), 0)           # a node without scores
    width = np.full((*shape, len(levels)), np.inf)
    count = np.zeros((*shape, len(levels)), np.int64)
    for leaf in np.ndindex(*shape):
        for depth in range(len(shape), -1, -1):          # the leaf, then its parents
            q, n = nodes.get(leaf[:depth], empty)
            todo = (count[leaf] == 0) & ((n >= MIN_COUNT) & np.isfinite(q) | (depth == 0))
            width[leaf][todo], count[leaf][todo] = q[todo], n
    return edges, np.maximum.accumulate(width, axis=-1), count


def _node_quantiles(scores: np.ndarray, idx: np.ndarray, shape: tuple[int, ...],
                    levels: np.ndarray) -> dict[tuple, tuple[np.ndarray, int]]:
    """Each node of the bins' tree that holds scores (a leaf's first ``depth`` bin indices,
    the root ``()`` included), its quantiles at ``levels`` and its count: each computed once
    (a table is refitted many times over in :mod:`train.evaluation.coverage_band`)."""
    out: dict[tuple, tuple[np.ndarray, int]] = {}
    for depth in range(len(shape) + 1):
        key = np.ravel_multi_index(idx[:, :depth].T, shape[:depth]) if depth else \
            np.zeros(len(scores), np.int64)
        order = np.argsort(key, kind="stable")
        ids, first, counts = np.unique(key[order], return_index=True, return_counts=True)
        for k, a, n in zip(ids, first, counts, strict=True):
            node = np.unravel_index(k, shape[:depth]) if depth else ()
            out[tuple(int(i) for i in node)] = (
                conformal_quantile(scores[order[a:a + n]], levels), int(n))
    return out

"""How far off a prediction may be: split conformal intervals, binned (Mondrian), as a table.

A point's score is its displacement error norm, so its interval is a sphere of a radius; the
force's is |dF error|, an interval dF +- half-width. Calibrated on presses the model did not
train on (each fold's validation presses, :mod:`train.training.calibrate`), the radius at
level q of a bin is its calibration scores' ``ceil((n + 1) q)``-th smallest (the finite-sample
correction: with n exchangeable scores, a new one falls at or below it with probability at
least q; infinite where ``ceil((n + 1) q) > n``).

The bins (Mondrian: a quantile per bin, so a point beside the tip and one far from it get their
own radii) are by what changes the error: a point's distance from the tip's path (segment tip
start to tip end), the press's depth (how far the tip moves, |tip end - tip start|) and the tip
start's height above the surface. Their edges are the calibration's own quantiles
(:data:`SPLITS`: quartiles of the distance, medians of the other two), so every lab's and the
MSM's scales fit. A bin with fewer than :data:`MIN_COUNT` scores (or an infinite quantile) at
a level takes its parent's: the same bins without the tip's height, then without the depth
too, then every score (the fallback is resolved once, when the table is made, and each radius
records how many scores it stands on). The force is binned by depth and height alike.

The table covers levels 0.01 .. 0.99 in steps of 0.01; a level between them takes the next
above (the interval is then at least as wide as asked). Plain numpy and plain types: a
checkpoint keeps it (``to_dict``), an ONNX file carries it in its metadata, and the predictor
looks a press up in microseconds (:meth:`Bins.widths`).
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass
from functools import cached_property

import numpy as np

LEVELS = tuple(round(0.01 * i, 2) for i in range(1, 100))   # the levels a table holds
REPORTED = (0.8, 0.9, 0.95)                                   # what evaluation reports
MIN_COUNT = 30        # scores a bin needs before its own quantile is used
# the calibration quantiles that make each feature's bin edges: the distance from the tip's
# path in quarters, the press's depth and the tip's height in halves
SPLITS = {"distance": (0.25, 0.5, 0.75), "depth": (0.5,), "height": (0.5,)}
POINT_FEATURES = ("distance", "depth", "height")
FORCE_FEATURES = ("depth", "height")


def level_index(level: float) -> int:
    """The index in :data:`LEVELS` of ``level`` (the next level above it where it lies
    between two); ValueError in one line outside (0, 1) or above the highest."""
    if not (isinstance(level, int | float) and math.isfinite(level) and 0 < level < 1):
        raise ValueError(f"level must lie in (0, 1), got {level!r}")
    i = max(math.ceil(round(level * 100, 9)) - 1, 0)
    if i >= len(LEVELS):
        raise ValueError(f"level {level:g}: intervals are calibrated up to {LEVELS[-1]:g}")
    return i


def conformal_quantile(scores: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """The split-conformal quantile of ``scores`` (n,) at each of ``levels`` (Q,): the
    ``ceil((n + 1) q)``-th smallest score, infinite where that exceeds n."""
    s = np.sort(np.asarray(scores, dtype=np.float64))
    rank = np.ceil(np.round((len(s) + 1) * np.asarray(levels), 9)).astype(np.int64)
    out = np.full(len(rank), np.inf)
    ok = rank <= len(s)
    out[ok] = s[rank[ok] - 1]
    return out


def path_distance(points: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Distance (..., N) of each point (..., N, 3) from the segment ``start``-``end`` (..., 3)
    (from ``start`` where they coincide)."""
    axis = (end - start)[..., None, :]
    rel = points - start[..., None, :]
    length2 = (axis * axis).sum(-1)
    t = np.clip((rel * axis).sum(-1) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
    return np.sqrt(((rel - t[..., None] * axis) ** 2).sum(-1))


def bin_edges(values: np.ndarray, splits: tuple[float, ...]) -> tuple[float, ...]:
    """A feature's bin edges: ``values``' quantiles at ``splits`` (duplicates dropped)."""
    return tuple(float(v) for v in np.unique(np.quantile(values, splits)))


@dataclass(frozen=True)
class Bins:
    """Binned (Mondrian) quantiles of one score: per feature its edges (bin i holds values
    in [edge i-1, edge i)), and per bin and level the width (radius or half-width, inf where
    the calibration cannot bound it) and how many calibration scores it stands on."""

    edges: tuple[tuple[float, ...], ...]
    width: np.ndarray          # (*shape, Q) float64
    count: np.ndarray          # (*shape, Q) int64

    @classmethod
    def fit(cls, scores: np.ndarray, features: np.ndarray, splits: tuple[tuple[float, ...], ...]
            ) -> Bins:
        """From scores (M,) and their features (M, K), each feature binned at its
        calibration quantiles ``splits[k]``; a bin short of :data:`MIN_COUNT` scores (or
        unbounded at a level) takes its parent's (the last feature dropped first)."""
        edges = tuple(bin_edges(features[:, k], s) for k, s in enumerate(splits))
        idx = np.stack([np.searchsorted(e, features[:, k], side="right")
                        for k, e in enumerate(edges)], 1)
        shape = tuple(len(e) + 1 for e in edges)
        levels = np.asarray(LEVELS)
        width = np.full((*shape, len(levels)), np.inf)
        count = np.zeros((*shape, len(levels)), np.int64)
        for leaf in np.ndindex(*shape):
            for depth in range(len(shape), -1, -1):          # the leaf, then its parents
                mine = (idx[:, :depth] == leaf[:depth]).all(1)
                q = conformal_quantile(scores[mine], levels)
                todo = (count[leaf] == 0) & ((mine.sum() >= MIN_COUNT) & np.isfinite(q)
                                             | (depth == 0))
                width[leaf][todo], count[leaf][todo] = q[todo], mine.sum()
        return cls(edges, width, count)

    def widths(self, level: int, *features: np.ndarray | float) -> np.ndarray:
        """The width at level index ``level`` for each value of ``features`` (one array or
        scalar per feature, broadcast together)."""
        flat = self.width[..., level].ravel()
        i = 0
        for e, f in zip(self.edges, features, strict=True):
            i = i * (len(e) + 1) + np.searchsorted(e, f, side="right")
        return flat[i]

    def row(self, level: int, *rest: float) -> np.ndarray:
        """The widths (bins of the first feature,) at level index ``level`` for one value of
        each later feature (looked up in Python: a press's scalars)."""
        at = (slice(None), *(bisect_right(e, v) for e, v in zip(self.edges[1:], rest,
                                                                 strict=True)), level)
        return self.width[at]

    def at(self, level: int, *values: float) -> float:
        """The width at level index ``level`` for one value of each feature."""
        index = tuple(bisect_right(e, v) for e, v in zip(self.edges, values, strict=True))
        return float(self.width[(*index, level)])

    @cached_property
    def first_squared(self) -> np.ndarray:
        """The first feature's edges squared (a distance's bins from its square)."""
        return np.square(np.asarray(self.edges[0]))

    def to_dict(self) -> dict:
        """Plain types (an unbounded width as None)."""
        return {"edges": [list(e) for e in self.edges],
                "width": np.where(np.isfinite(self.width), self.width, None).tolist(),
                "count": self.count.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> Bins:
        """From :meth:`to_dict`'s form; ValueError where the shapes do not agree."""
        edges = tuple(tuple(float(v) for v in e) for e in d["edges"])
        shape = (*(len(e) + 1 for e in edges), len(LEVELS))
        width = np.array(d["width"], dtype=np.float64)
        count = np.array(d["count"], dtype=np.int64)
        if width.shape != shape or count.shape != shape:
            raise ValueError(f"interval bins of shape {width.shape}, their edges need {shape}")
        if (width < 0).any() or (count < 1).any():
            raise ValueError("interval widths must be non-negative, each on some scores")
        return cls(edges, np.where(np.isnan(width), np.inf, width), count)


@dataclass(frozen=True)
class IntervalTable:
    """The intervals a checkpoint keeps: the points' radii (binned by distance from the
    tip's path, depth, height), the force's half-widths (by depth, height), and how many
    presses, examples and points they were calibrated on."""

    points: Bins
    force: Bins
    presses: int
    examples: int

    @classmethod
    def fit(cls, point_scores: np.ndarray, point_features: np.ndarray,
            force_scores: np.ndarray, force_features: np.ndarray, presses: int
            ) -> IntervalTable:
        """From the calibration's point scores (M,) m with features (M, 3) (distance, depth,
        height) and force scores (E,) N with features (E, 2) (depth, height)."""
        return cls(Bins.fit(point_scores, point_features,
                            tuple(SPLITS[f] for f in POINT_FEATURES)),
                   Bins.fit(force_scores, force_features,
                            tuple(SPLITS[f] for f in FORCE_FEATURES)),
                   presses, len(force_scores))

    def to_dict(self) -> dict:
        """Plain types, for a checkpoint loaded with ``weights_only`` and for JSON."""
        return {"levels": list(LEVELS), "point_features": list(POINT_FEATURES),
                "force_features": list(FORCE_FEATURES), "min_count": MIN_COUNT,
                "points": self.points.to_dict(), "force": self.force.to_dict(),
                "presses": self.presses, "examples": self.examples}

    @classmethod
    def from_dict(cls, d: dict) -> IntervalTable:
        """From :meth:`to_dict`'s form; ValueError where it is not one."""
        if list(d["levels"]) != list(LEVELS):
            raise ValueError("interval levels are not 0.01 .. 0.99")
        return cls(Bins.from_dict(d["points"]), Bins.from_dict(d["force"]),
                   int(d["presses"]), int(d["examples"]))

    def radii(self, level: int, distance: np.ndarray, depth: float, height: float
              ) -> np.ndarray:
        """Each point's radius (N,) m at level index ``level``, from its distance from the
        tip's path (N,) and the press's depth and tip height."""
        return self.points.widths(level, distance, depth, height)


@dataclass(frozen=True)
class Interval:
    """How far a prediction may be off, at ``level``: each point's radius (N,) m about its
    predicted position, the change of force's interval (low, high) N, and whether they hold
    (False beyond the training envelope, where they were not calibrated)."""

    level: float
    radius: np.ndarray
    force: tuple[float, float]
    holds: bool


def force_interval(table: IntervalTable, level: float, condition: np.ndarray, height: float,
                   dforce: float) -> tuple[float, float]:
    """The change of force's interval (low, high) N at ``level`` for a press C (6,) whose tip
    starts ``height`` above the surface, about the predicted ``dforce``."""
    half = table.force.at(level_index(level), _depth(condition), height)
    return dforce - half, dforce + half


def interval(table: IntervalTable, level: float, points: np.ndarray, condition: np.ndarray,
             height: float, dforce: float, holds: bool) -> Interval:
    """The :class:`Interval` of one prediction: its input points (N, 3), C (6,), the tip
    start's height above the surface, the predicted change of force, and whether it holds.
    A lookup: each point's squared distance from the tip's path binned, the press's depth
    and height looked up once."""
    i, depth = level_index(level), _depth(condition)
    bins = table.points
    near = np.searchsorted(bins.first_squared, _path_distance2(points, condition),
                           side="right")
    half = table.force.at(i, depth, height)
    return Interval(level, bins.row(i, depth, height)[near], (dforce - half, dforce + half),
                    holds)


def _path_distance2(points: np.ndarray, condition: np.ndarray) -> np.ndarray:
    """The squared distance (N,) of each point (N, 3) from the tip's path, C (6,) (few
    numpy calls: this is most of a known mesh's interval)."""
    start, axis = condition[:3], condition[3:] - condition[:3]
    rel = points - start
    length2 = float(axis @ axis)
    if length2 > 0:
        t = rel @ (axis / length2)
        np.minimum(np.maximum(t, 0.0, out=t), 1.0, out=t)
        rel -= np.multiply.outer(t, axis)
    return np.einsum("ij,ij->i", rel, rel)


def _depth(condition: np.ndarray) -> float:
    """How far the tip moves, |tip end - tip start| (m)."""
    axis = condition[3:] - condition[:3]
    return math.sqrt(float(axis @ axis))

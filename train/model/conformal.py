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
(:data:`SPLITS`: of the distance its nearest tenth and quartiles, medians of the other two), so
every lab's and the MSM's scales fit. A point within
:data:`~train.model.normalise.TIP_POINT` of the path is the tip's own (a lab's tip marker: its
error is a fraction of its neighbours') and has a distance bin of its own (:data:`LEADS`), the
quantiles being of the surface's points alone. With the tip's point and the markers up to
30 mm in one bin, one radius was too wide for the tip and too narrow 10-20 mm from the path,
where the error is largest (docs/results.md). A bin with fewer than :data:`MIN_COUNT` scores
(or an infinite quantile) at a level takes its parent's: the same bins without the tip's
height, then without the depth too, then every score (the fallback is resolved once, when the
table is made, and each radius records how many scores it stands on). The force is binned by
depth and height alike.

The table covers levels 0.01 .. 0.99 in steps of 0.01; a level between them takes the next
above (the interval is then at least as wide as asked). Plain numpy and plain types: a
checkpoint keeps it (``to_dict``), an ONNX file carries it in its metadata, and the predictor
looks a press up in microseconds (:meth:`Bins.widths`).
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np

from train.model.normalise import TIP_POINT

LEVELS = tuple(round(0.01 * i, 2) for i in range(1, 100))   # the levels a table holds
REPORTED = (0.8, 0.9, 0.95)                                   # what evaluation reports
MIN_COUNT = 30        # scores a bin needs before its own quantile is used
ROUNDING = 1e-9       # m: a kept lookup measures its bins again when a point is this near an edge
# the calibration quantiles that make each feature's bin edges: the distance from the tip's
# path in its nearest tenth and quarters (the error falls steeply over the nearest 20 mm), the
# press's depth and the tip's height in halves
SPLITS = {"distance": (0.1, 0.25, 0.5, 0.75), "depth": (0.5,), "height": (0.5,)}
# a feature's fixed first edge: below it a bin of its own (the tip's own point), the quantiles
# of the rest
LEADS = {"distance": TIP_POINT}
POINT_FEATURES = ("distance", "depth", "height")
FORCE_FEATURES = ("depth", "height")


def level_index(level: float) -> int:
    """The index in :data:`LEVELS` of ``level`` (the next level above it where it lies
    between two); ValueError in one line outside (0, 1) or above the highest."""
    try:
        return _level_index(level)
    except TypeError:                  # unhashable: no level
        raise ValueError(f"level must lie in (0, 1), got {level!r}") from None


@lru_cache(maxsize=256)
def _level_index(level: float) -> int:
    """:func:`level_index`, kept per level asked (a haptic loop asks one, call after call)."""
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


def bin_edges(values: np.ndarray, splits: tuple[float, ...], lead: float | None = None
              ) -> tuple[float, ...]:
    """A feature's bin edges: ``values``' quantiles at ``splits`` (duplicates dropped); with
    ``lead``, that edge first and the quantiles of the values at or above it (where any are)."""
    if lead is None:
        return tuple(float(v) for v in np.unique(np.quantile(values, splits)))
    rest = values[values >= lead]
    above = np.unique(np.quantile(rest, splits)) if len(rest) else np.empty(0)
    return (float(lead), *(float(v) for v in above[above > lead]))


@dataclass(frozen=True)
class Bins:
    """Binned (Mondrian) quantiles of one score: per feature its edges (bin i holds values
    in [edge i-1, edge i)), and per bin and level the width (radius or half-width, inf where
    the calibration cannot bound it) and how many calibration scores it stands on."""

    edges: tuple[tuple[float, ...], ...]
    width: np.ndarray          # (*shape, Q) float64
    count: np.ndarray          # (*shape, Q) int64

    @classmethod
    def fit(cls, scores: np.ndarray, features: np.ndarray, splits: tuple[tuple[float, ...], ...],
            lead: tuple[float | None, ...] | None = None) -> Bins:
        """From scores (M,) and their features (M, K), each feature binned at its
        calibration quantiles ``splits[k]``; with ``lead[k]`` a value, the values below it
        are a bin of their own and the quantiles are of the rest (:func:`bin_edges`). A bin
        short of :data:`MIN_COUNT` scores (or unbounded at a level) takes its parent's (the
        last feature dropped first)."""
        lead = lead or (None,) * len(splits)
        edges = tuple(bin_edges(features[:, k], s, a)
                      for k, (s, a) in enumerate(zip(splits, lead, strict=True)))
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
        each later feature (looked up in Python: a press's scalars; each row kept once
        asked)."""
        key = (level, *map(bisect_right, self.edges[1:], rest))
        row = self._kept.get(key)
        if row is None:
            row = self._kept[key] = np.ascontiguousarray(self.width[(slice(None), *key[1:],
                                                                     level)])
        return row

    def at(self, level: int, *values: float) -> float:
        """The width at level index ``level`` for one value of each feature."""
        key = (level, *map(bisect_right, self.edges, values), None)
        width = self._kept.get(key)
        if width is None:
            width = self._kept[key] = float(self.width[(*key[1:-1], level)])
        return width

    @cached_property
    def _kept(self) -> dict[tuple, np.ndarray | float]:
        """The rows and widths asked so far (:meth:`row`, :meth:`at`), by their bins."""
        return {}

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
                            tuple(SPLITS[f] for f in POINT_FEATURES),
                            tuple(LEADS.get(f) for f in POINT_FEATURES)),
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

    def press(self, level: int, depth: float, height: float) -> tuple[np.ndarray, float]:
        """For a press of ``depth`` whose tip starts ``height`` above the surface, at level
        index ``level``: the points' radii by distance bin and the force's half-width (each
        pair kept once asked: one lookup a press)."""
        pd, ph = self.points.edges[1:]
        fd, fh = self.force.edges
        key = (level, bisect_right(pd, depth), bisect_right(ph, height),
               bisect_right(fd, depth), bisect_right(fh, height))
        kept = self._kept.get(key)
        if kept is None:
            kept = self._kept[key] = (self.points.row(level, depth, height),
                                      self.force.at(level, depth, height))
        return kept

    @cached_property
    def _kept(self) -> dict[tuple[int, ...], tuple[np.ndarray, float]]:
        return {}

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


def interval(table: IntervalTable, level: float, points: np.ndarray | SceneLookup,
             condition: np.ndarray | list[float], height: float, dforce: float, holds: bool
             ) -> Interval:
    """The :class:`Interval` of one prediction: its input points (N, 3) (or a scene's
    :class:`SceneLookup`, kept press after press), C (6,) (an array, or its plain floats),
    the tip start's height above the surface, the predicted change of force, and whether it
    holds. A lookup: each point's squared distance from the tip's path binned, the press's
    depth and height looked up once; the radii are read-only (a scene's lookup hands the same
    array out while the press's bins stand)."""
    i = level_index(level)
    scene = points if isinstance(points, SceneLookup) else SceneLookup(points)
    c = condition if isinstance(condition, list) else np.asarray(condition).tolist()
    near, depth = scene.near(table.points.first_squared, c)
    row, half = table.press(i, depth, height)
    return Interval(level, scene.radii(row, near), (dforce - half, dforce + half), holds)


class SceneLookup:
    """A scene's points as its interval lookups keep them (a known mesh, press after press):
    in float64; for the last tip start their offsets from it and squared norms; for the last
    press measured (and table) each point's distance bin and how far the tip's path may move
    before any point changes bin. A point's distance from a segment moves by no more than
    the segment's ends do, so a press whose start and end lie within that margin of the
    measured one's has its bins (a haptic loop's tip, moving micrometres a call, is measured
    again only when a point nears a bin's edge). Few numpy calls a press: this is most of a
    known mesh's interval."""

    __slots__ = ("points", "_start", "_rel", "_rel2", "_press", "_unit", "_along", "_near",
                 "_radii")

    def __init__(self, points: np.ndarray) -> None:
        self.points = np.asarray(points, dtype=np.float64)
        n = len(self.points)
        self._start: list[float] = []
        self._rel, self._rel2 = np.empty((n, 3)), np.empty(n)
        # the press measured: its C, the edges, each point's bin, the margin (m)
        self._press: tuple[list[float], np.ndarray | None, np.ndarray, float] = \
            ([], None, np.empty(0, np.int64), -1.0)
        self._unit, self._along, self._near = np.empty(3), np.empty(n), np.empty(n)
        self._radii: tuple[np.ndarray | None, np.ndarray | None, np.ndarray] = \
            (None, None, np.empty(0))              # the last radii, of (row, bins)

    def radii(self, row: np.ndarray, bins: np.ndarray) -> np.ndarray:
        """Each point's radius (N,), read-only: its bin's in ``row``, kept while the row
        and the bins are the last call's (a moving tip's press after press)."""
        kept_row, kept_bins, radii = self._radii
        if row is not kept_row or bins is not kept_bins:
            radii = row[bins]
            radii.flags.writeable = False
            self._radii = (row, bins, radii)
        return radii

    def near(self, edges2: np.ndarray, c: list[float]) -> tuple[np.ndarray, float]:
        """Each point's bin (N,) among squared distance edges ``edges2`` from the tip's path
        of C (6 plain floats: few numpy calls), and the press's depth |tip end - tip start|
        (m)."""
        start, end = c[:3], c[3:]
        depth = math.dist(start, end)
        seen, kept, bins, margin = self._press
        if kept is edges2 and max(math.dist(start, seen[:3]), math.dist(end, seen[3:])) \
                < margin:
            return bins, depth
        bins, margin = self._bins(edges2, start, end, depth)
        self._press = (c, edges2, bins, margin)
        return bins, depth

    def _bins(self, edges2: np.ndarray, start: list[float], end: list[float], length: float
              ) -> tuple[np.ndarray, float]:
        """Each point's bin, and the least distance of any point from a bin's edge less
        :data:`ROUNDING` (0 where none is farther)."""
        if start != self._start:
            np.subtract(self.points, start, out=self._rel)
            np.einsum("ij,ij->i", self._rel, self._rel, out=self._rel2)
            self._start = start
        d2 = self._rel2
        if length > 0:
            # b: each point's offset along the path; v = clip(b, 0, length), the nearest
            # point of the segment's; |rel - v unit|^2 = |rel|^2 + v (v - 2 b)
            u, d2, v = self._unit, self._along, self._near
            u[0] = (end[0] - start[0]) / length
            u[1] = (end[1] - start[1]) / length
            u[2] = (end[2] - start[2]) / length
            np.dot(self._rel, u, out=d2)
            np.maximum(d2, 0.0, out=v)
            np.minimum(v, length, out=v)
            d2 *= -2.0
            d2 += v
            d2 *= v
            d2 += self._rel2
        edges = np.sqrt(edges2)
        gap = np.abs(np.subtract.outer(np.sqrt(np.maximum(d2, 0.0)), edges)).min() \
            if len(edges) else np.inf
        return edges2.searchsorted(d2, "right"), max(float(gap) - ROUNDING, 0.0)


def _depth(condition: np.ndarray) -> float:
    """How far the tip moves, |tip end - tip start| (m)."""
    axis = condition[3:] - condition[:3]
    return math.sqrt(float(axis @ axis))

"""A table looked up press after press: what :class:`train.Predictor` answers with a level.

A haptic loop presses one mesh a thousand times a second, its tip moving micrometres a call,
so the lookup keeps what a press does not change. Per table (:class:`TableLookup`): each
press's radii row (by distance bin) and force half-width, by the bins of its depth and
height. Per scene (:class:`SceneLookup`): the last tip start's height, and each point's
distance bin with its margin, kept while the press's ends stay nearer to the last press's
than the point's distance lay from a bin's edge (a point's distance from a segment moves no
more than the segment's ends do); a point the press has moved past its margin is measured
again. Every feature is measured by :mod:`train.intervals.features`, as calibration measured
it.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass

import numpy as np

from train.intervals.features import path_distance, press_depth, start_height
from train.intervals.table import IntervalTable

ROUNDING = 1e-9       # m: kept bins are measured again when a point is this near an edge


@dataclass(frozen=True)
class Interval:
    """How far a prediction may be off, at ``level``: each point's radius (N,) m about its
    predicted position, the change of force's interval (low, high) N, and whether they hold
    (False beyond the training envelope, where they were not calibrated)."""

    level: float
    radius: np.ndarray
    force: tuple[float, float]
    holds: bool


class TableLookup:
    """A table as a predictor reads it: a press's radii (by distance bin) and force
    half-width at a level index, found by the bins of its depth and height and kept once
    asked (one dict lookup a press)."""

    def __init__(self, table: IntervalTable) -> None:
        self.table = table
        self.distance_edges = np.asarray(table.points.edges[0], dtype=np.float64)
        self._kept: dict[tuple[int, ...], tuple[np.ndarray, float]] = {}

    def press(self, level: int, depth: float, height: float) -> tuple[np.ndarray, float]:
        """The radii row (distance bins,) m, read-only, and the force's half-width N at level
        index ``level`` of a press of ``depth`` whose tip starts ``height`` above the
        surface."""
        (pd, ph), (fd, fh) = self.table.points.edges[1:], self.table.force.edges
        key = (level, bisect_right(pd, depth), bisect_right(ph, height),
               bisect_right(fd, depth), bisect_right(fh, height))
        kept = self._kept.get(key)
        if kept is None:
            row = np.ascontiguousarray(self.table.points.width[:, key[1], key[2], level])
            row.flags.writeable = False
            kept = self._kept[key] = (row, float(self.table.force.width[key[3], key[4], level]))
        return kept


@dataclass(frozen=True)
class Measured:
    """Each point's distance bin for a press C, and its margin: how far the press's ends may
    move from C's before the point can change bin (m); the least of them."""

    c: list[float]
    edges: np.ndarray | None
    bins: np.ndarray
    margin: np.ndarray
    least: float


class SceneLookup:
    """A scene's points as its lookups keep them (a known mesh, press after press), in
    float64: the last tip start and its height, the last press's distance bins and margins
    (:class:`Measured`), and the last radii."""

    __slots__ = ("points", "_start", "_measured", "_radii")

    def __init__(self, points: np.ndarray) -> None:
        self.points = np.asarray(points, dtype=np.float64)
        self._start: tuple[list[float] | None, float] = (None, 0.0)
        self._measured = Measured([], None, np.empty(0, np.int64), np.empty(0), -1.0)
        self._radii: tuple[np.ndarray | None, np.ndarray | None, np.ndarray] = \
            (None, None, np.empty(0))              # the last radii, of (row, bins)

    def interval(self, table: TableLookup, level: float, index: int, c: list[float],
                 dforce: float, holds: bool) -> Interval:
        """The :class:`Interval` at ``level`` (its index ``index``) of a press C (six plain
        floats) on this scene, about the predicted change of force ``dforce``; its radii
        are read-only (the same array, press after press, while the press's bins stand)."""
        row, half = table.press(index, press_depth(c), self._height(c[:3]))
        bins = self.distance_bins(table.distance_edges, c)
        kept_row, kept_bins, radii = self._radii
        if row is not kept_row or bins is not kept_bins:
            radii = row[bins]
            radii.flags.writeable = False
            self._radii = (row, bins, radii)
        return Interval(level, radii, (dforce - half, dforce + half), holds)

    def force_interval(self, table: TableLookup, index: int, c: list[float], dforce: float
                       ) -> tuple[float, float]:
        """The change of force's interval (low, high) N at level index ``index`` of a press
        C (six plain floats) on this scene, about the predicted ``dforce``."""
        half = table.press(index, press_depth(c), self._height(c[:3]))[1]
        return dforce - half, dforce + half

    def _height(self, start: list[float]) -> float:
        """The tip start's height above the scene, kept for the last start (a haptic loop's
        tip moves its end, call after call)."""
        if start != self._start[0]:
            self._start = (start, start_height(self.points, np.array(start)))
        return self._start[1]

    def distance_bins(self, edges: np.ndarray, c: list[float]) -> np.ndarray:
        """Each point's distance bin (N,) among ``edges`` for the press C (six plain
        floats): the last press's bins, but for the points whose margin C has moved past (the
        farther of its ends' distances from the last press's), which are measured again, the
        others' margins shrinking by as much; every point measured where they are a quarter
        of the points or more."""
        m = self._measured
        if m.edges is not edges:
            return self._measure(edges, c)
        moved = max(math.dist(c[:3], m.c[:3]), math.dist(c[3:], m.c[3:]))
        if moved < m.least:
            return m.bins
        near = np.flatnonzero(m.margin <= moved)
        if 4 * len(near) >= len(m.bins):
            return self._measure(edges, c)
        distance = path_distance(self.points[near], np.array(c[:3]), np.array(c[3:]))
        bins, margin = m.bins.copy(), m.margin - moved
        bins[near] = edges.searchsorted(distance, "right")
        margin[near] = _margin(distance, edges)
        self._measured = Measured(c, edges, bins, margin, float(margin.min()))
        return bins

    def _measure(self, edges: np.ndarray, c: list[float]) -> np.ndarray:
        """Each point's distance bin for the press C, every point measured."""
        distance = path_distance(self.points, np.array(c[:3]), np.array(c[3:]))
        margin = _margin(distance, edges)
        self._measured = Measured(c, edges, edges.searchsorted(distance, "right"), margin,
                                  float(margin.min()))
        return self._measured.bins


def _margin(distance: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """How far each distance (n,) lies from the nearest edge, less :data:`ROUNDING` (what a
    point's distance, measured again, may differ by in rounding); infinite without edges."""
    if not len(edges):
        return np.full(len(distance), np.inf)
    return np.abs(np.subtract.outer(distance, edges)).min(1) - ROUNDING

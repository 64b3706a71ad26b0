"""The lookup against the table read directly: each point's bin is that of its Euclidean
distance from the tip's path, press after press (the kept bins reused only while no point can
have crossed an edge); a kept scene's interval is a fresh one's; and a press calibrated and
then looked up gets the radius the table gives its calibrated features, to the last bit, where
they lie on a bin's edge too."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.interval_table import near_far

import train.intervals.lookup as lookup
from train.intervals.features import path_distance, press_features, start_height
from train.intervals.levels import level_index
from train.intervals.lookup import SceneLookup, TableLookup
from train.intervals.table import IntervalTable


def _distance(points: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Each point's distance from the press's path, in float64 from float32 inputs."""
    c = c.astype(np.float64)
    return path_distance(points.astype(np.float64), c[:3], c[3:])


def test_the_scenes_lookup_bins_points_by_their_distance_from_the_path() -> None:
    """Kept press after press (the tip's end moving, then its start, then another table),
    each point's bin is that of its Euclidean distance from the segment."""
    rng = np.random.default_rng(5)
    points = rng.uniform(-0.05, 0.05, (40, 3)).astype(np.float32)
    edges = np.array([1e-4, 0.01, 0.02, 0.04])
    other = np.array([0.005, 0.03])
    scene = SceneLookup(points)
    start = np.array([0.001, -0.002, 0.01], np.float32)
    presses = [np.r_[start, start + [0, 0, -dz]] for dz in (0.0, 0.002, 0.004, 0.004)]
    presses += [np.r_[start + [0.003, 0, 0], start + [0.003, 0.001, -0.02]]]
    for c in presses:
        for e in (edges, edges, other):
            c = c.astype(np.float32)
            got = scene.distance_bins(e, c.tolist())
            np.testing.assert_array_equal(got, np.searchsorted(e, _distance(points, c), "right"))


def test_a_tip_moving_in_small_steps_keeps_the_bins_exact(monkeypatch: pytest.MonkeyPatch
                                                           ) -> None:
    """A haptic loop's tip: its end (then its start) moving 20 um a call, points strewn
    across the bins' edges; every call's bins are those of the Euclidean distance (a point's
    bin is kept only while it cannot have crossed an edge; the others are measured again,
    and all of them where they are a quarter of the points)."""
    measured: list[int] = []
    exact = lookup.path_distance
    monkeypatch.setattr(lookup, "path_distance",
                        lambda p, *a: measured.append(len(p)) or exact(p, *a))
    rng = np.random.default_rng(7)
    points = rng.uniform(-0.03, 0.03, (300, 3)).astype(np.float32)
    edges = np.array([1e-4, 0.005, 0.01, 0.02])
    scene = SceneLookup(points)
    c = np.array([0.0, 0.0, 0.005, 0.0, 0.0, 0.005], np.float32)
    for k in range(600):
        c[5 if k < 300 else 0] -= 2e-5
        c[4] += 1e-6 * rng.standard_normal()
        measured.append(0)
        got = scene.distance_bins(edges, c.tolist())
        np.testing.assert_array_equal(got, np.searchsorted(edges, _distance(points, c), "right"))
    calls = np.add.reduceat(measured, np.flatnonzero(np.r_[np.array(measured) == 0]))
    ways = {"kept": (calls == 0).sum(), "some": ((calls > 0) & (calls < 300)).sum(),
            "all": (calls == 300).sum()}
    assert all(ways.values()), ways         # each way was taken


def test_an_interval_from_a_kept_scene_is_the_tables() -> None:
    rng = np.random.default_rng(6)
    scores, feats = near_far(rng, 4000)
    table = IntervalTable.fit(scores, feats, np.abs(rng.normal(0, 0.1, 400)),
                              rng.uniform(0, 1e-3, (400, 2)), presses=3)
    kept, i = TableLookup(table), level_index(0.9)
    points = rng.uniform(-0.04, 0.04, (26, 3)).astype(np.float32)
    scene = SceneLookup(points)
    for z in (0.001, 0.002, 0.002):
        c = np.array([0, 0, 0.001, 0, 0, 0.001 - z], np.float32)
        got = scene.interval(kept, 0.9, i, c.tolist(), 0.3, True)
        fresh = SceneLookup(points).interval(TableLookup(table), 0.9, i, c.tolist(), 0.3, True)
        np.testing.assert_array_equal(got.radius, fresh.radius)
        assert got.force == fresh.force and got.level == 0.9 and got.holds
        height = start_height(points.astype(np.float64), c[:3].astype(np.float64))
        depth = np.float64(c[2]) - np.float64(c[5])
        np.testing.assert_array_equal(got.radius, table.radii(i, _distance(points, c), depth,
                                                              height))
        half = table.force.widths(i, depth, height)
        assert got.force == (0.3 - half, 0.3 + half)
        assert not got.radius.flags.writeable     # shared press after press: read-only


def test_a_calibrated_press_looked_up_gets_its_calibrated_radius() -> None:
    """Presses of a 7 x 7 surface, their features measured as calibration measures them
    (float32 data in float64) and a table fitted on them, so that many features lie exactly
    on an edge: looked up as a predictor looks a press up (C as float32 plain floats), each
    point's radius and the force's half-width are the table's for the calibrated features."""
    rng = np.random.default_rng(8)
    g = (np.arange(7) + 0.5) / 7 * 0.1
    surface = np.stack([*np.meshgrid(g, g), np.zeros((7, 7))], -1).reshape(-1, 3)
    presses = 41
    tips = np.c_[rng.uniform(0.03, 0.07, (presses, 2)), rng.integers(0, 3, presses) * 1e-3]
    cond = np.c_[tips, tips - np.c_[np.zeros((presses, 2)),
                                   rng.integers(1, 6, presses) * 1e-3]].astype(np.float32)
    points = np.broadcast_to(surface.astype(np.float32), (presses, 49, 3))
    f = press_features(points.astype(np.float64), np.ones((presses, 49), bool),
                       cond.astype(np.float64))
    feats = f.of_points().reshape(-1, 3)
    table = IntervalTable.fit(rng.exponential(1e-4, len(feats)), feats,
                              rng.exponential(0.1, presses), f.of_force(), presses)
    on_edge = [np.isin(feats[:, k], e).sum() for k, e in enumerate(table.points.edges)]
    assert on_edge[0] > 0 and on_edge[1] > 0      # distances and depths on an edge
    kept, scene = TableLookup(table), SceneLookup(points[0])
    for level in (0.5, 0.9, 0.95):
        i = level_index(level)
        for b in range(presses):
            sure = scene.interval(kept, level, i, cond[b].tolist(), 0.0, True)
            np.testing.assert_array_equal(sure.radius, table.radii(i, *f.of_points()[b].T))
            assert sure.force[1] == table.force.widths(i, *f.of_force()[b])

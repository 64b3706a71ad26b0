"""The conformal table against known truth: exchangeable scores whose coverage is known in
closed form, bins that separate near and far points, the fallback of a thin bin, refusals."""

from __future__ import annotations

import json

import numpy as np
import pytest

from train.model.conformal import (
    LEVELS,
    MIN_COUNT,
    Bins,
    IntervalTable,
    SceneLookup,
    bin_edges,
    conformal_quantile,
    interval,
    level_index,
    path_distance,
)
from train.model.normalise import TIP_POINT

Z90 = 1.6448536269514722      # the standard normal's 95 % quantile: |N(0, s)|'s 90 %


@pytest.mark.parametrize("n", [19, 50, 99])
def test_split_conformal_coverage_is_the_finite_sample_value(n: int) -> None:
    """Exponential scores: a test score falls within the calibration's quantile with
    probability F(q_hat), whose mean over calibrations is ceil((n + 1) q) / (n + 1)."""
    rng = np.random.default_rng(n)
    level = 0.9
    q = np.array([conformal_quantile(rng.exponential(size=n), np.array([level]))[0]
                  for _ in range(4000)])
    covered = 1 - np.exp(-q)                        # F(q) of the exponential
    want = np.ceil((n + 1) * level) / (n + 1)
    assert covered.mean() == pytest.approx(want, abs=3 * covered.std() / np.sqrt(len(q)))
    assert covered.mean() >= level - 3 * covered.std() / np.sqrt(len(q))


def test_too_few_scores_cannot_bound_a_high_level() -> None:
    """Nine scores: ceil(10 x 0.95) = 10 > 9, so no finite radius holds at 95 %."""
    q = conformal_quantile(np.arange(1.0, 10.0), np.array([0.5, 0.9, 0.95]))
    assert q[0] == 5.0 and q[1] == 9.0 and np.isinf(q[2])


def _near_far(rng: np.random.Generator, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Scores |N(0, s)| with s = 1 mm within 10 mm of the tip's path and 0.1 mm beyond;
    the depth and height features carry nothing."""
    dist = rng.uniform(0, 0.04, m)
    sigma = np.where(dist < 0.01, 1e-3, 1e-4)
    feats = np.stack([dist, rng.uniform(1e-3, 2e-3, m), rng.uniform(0, 1e-3, m)], 1)
    return np.abs(rng.normal(0, sigma)), feats


def test_bins_give_points_beside_the_tip_their_own_radius() -> None:
    rng = np.random.default_rng(0)
    scores, feats = _near_far(rng, 8000)
    table = IntervalTable.fit(scores, feats, np.abs(rng.normal(0, 0.1, 400)),
                              rng.uniform(0, 1e-3, (400, 2)), presses=3)
    i = level_index(0.9)
    near = table.radii(i, np.array([0.001]), 1.5e-3, 5e-4)[0]
    far = table.radii(i, np.array([0.035]), 1.5e-3, 5e-4)[0]
    assert near == pytest.approx(Z90 * 1e-3, rel=0.15)      # the true 90 % radius there
    assert far == pytest.approx(Z90 * 1e-4, rel=0.15)
    # held-out scores drawn alike are covered at the level, near and far apart
    test, tf = _near_far(np.random.default_rng(1), 20000)
    inside = test <= table.radii(i, tf[:, 0], tf[:, 1], tf[:, 2])
    for part in (tf[:, 0] < 0.005, tf[:, 0] > 0.02):
        assert inside[part].mean() == pytest.approx(0.9, abs=0.02)


def _with_tip(rng: np.random.Generator, presses: int) -> tuple[np.ndarray, np.ndarray]:
    """A lab's presses: 25 surface points 9-80 mm from the tip's path, |N(0, s)| with
    s = 1 mm within 15 mm and 0.1 mm beyond, and the tip's own point on the path with
    s = 0.05 mm (its error a fraction of its neighbours')."""
    dist = np.c_[np.zeros((presses, 1)), rng.uniform(0.009, 0.08, (presses, 25))].ravel()
    sigma = np.where(dist == 0, 5e-5, np.where(dist < 0.015, 1e-3, 1e-4))
    feats = np.stack([dist, rng.uniform(1e-3, 2e-3, len(dist)),
                      rng.uniform(0, 1e-3, len(dist))], 1)
    return np.abs(rng.normal(0, sigma)), feats


def test_the_tips_own_point_has_a_bin_of_its_own() -> None:
    """The tip's point (on the path) gets its own 90 % radius, and the surface points near
    the path theirs: neither is the quantile of the two mixed."""
    rng = np.random.default_rng(3)
    scores, feats = _with_tip(rng, 400)
    table = IntervalTable.fit(scores, feats, np.abs(rng.normal(0, 0.1, 400)),
                              rng.uniform(0, 1e-3, (400, 2)), presses=3)
    assert table.points.edges[0][0] == TIP_POINT       # then the surface points' quantiles
    assert table.points.edges[0][1] > 0.009
    i = level_index(0.9)
    tip = table.radii(i, np.array([0.0]), 1.5e-3, 5e-4)[0]
    assert tip == pytest.approx(Z90 * 5e-5, rel=0.15)
    test, tf = _with_tip(np.random.default_rng(4), 4000)
    inside = test <= table.radii(i, tf[:, 0], tf[:, 1], tf[:, 2])
    for part in (tf[:, 0] == 0, (tf[:, 0] > 0) & (tf[:, 0] < 0.015), tf[:, 0] >= 0.03):
        assert inside[part].mean() == pytest.approx(0.9, abs=0.025)


def test_a_lead_edge_comes_first_and_the_quantiles_are_of_the_rest() -> None:
    values = np.r_[np.zeros(50), np.arange(1.0, 101.0)]
    assert bin_edges(values, (0.5,)) == (25.5,)
    assert bin_edges(values, (0.5,), lead=1e-4) == (1e-4, 50.5)
    assert bin_edges(np.zeros(5), (0.5,), lead=1e-4) == (1e-4,)       # nothing beyond it


def test_the_scenes_lookup_bins_points_by_their_distance_from_the_path() -> None:
    """Kept press after press (the tip's end moving, then its start, then another table),
    each point's bin is that of its Euclidean distance from the segment."""
    rng = np.random.default_rng(5)
    points = rng.uniform(-0.05, 0.05, (40, 3)).astype(np.float32)
    edges = (1e-4, 0.01, 0.02, 0.04)
    other = (0.005, 0.03)
    scene = SceneLookup(points)
    start = np.array([0.001, -0.002, 0.01], np.float32)
    presses = [np.r_[start, start + [0, 0, -dz]] for dz in (0.0, 0.002, 0.004, 0.004)]
    presses += [np.r_[start + [0.003, 0, 0], start + [0.003, 0.001, -0.02]]]
    for c in presses:
        for e in (edges, edges, other):
            c = c.astype(np.float32)
            d = path_distance(points.astype(np.float64), c[:3].astype(np.float64),
                              c[3:].astype(np.float64))
            got, depth = scene.near(np.square(np.array(e)), c.tolist())
            np.testing.assert_array_equal(got, np.searchsorted(e, d, side="right"))
            assert depth == pytest.approx(np.linalg.norm(c[3:] - c[:3]), rel=1e-6)


def test_a_tip_moving_in_small_steps_keeps_the_bins_exact() -> None:
    """A haptic loop's tip: its end (then its start) moving 20 um a call, points strewn
    across the bins' edges; every call's bins are those of the Euclidean distance (the
    kept bins are reused only while no point can have crossed an edge)."""
    rng = np.random.default_rng(7)
    points = rng.uniform(-0.03, 0.03, (300, 3)).astype(np.float32)
    edges = (1e-4, 0.005, 0.01, 0.02)
    edges2 = np.square(np.array(edges))
    scene = SceneLookup(points)
    c = np.array([0.0, 0.0, 0.005, 0.0, 0.0, 0.005], np.float32)
    reused = 0
    for k in range(600):
        c[5 if k < 300 else 0] -= 2e-5
        c[4] += 1e-6 * rng.standard_normal()
        before = scene._press[3]
        got, _ = scene.near(edges2, c.tolist())
        reused += scene._press[3] == before
        d = path_distance(points.astype(np.float64), c[:3].astype(np.float64),
                          c[3:].astype(np.float64))
        np.testing.assert_array_equal(got, np.searchsorted(edges, d, side="right"))
    assert reused > 0                       # the margin spared some calls the measurement


def test_an_interval_from_a_kept_scene_is_the_one_from_its_points() -> None:
    rng = np.random.default_rng(6)
    scores, feats = _near_far(rng, 4000)
    table = IntervalTable.fit(scores, feats, np.abs(rng.normal(0, 0.1, 400)),
                              rng.uniform(0, 1e-3, (400, 2)), presses=3)
    points = rng.uniform(-0.04, 0.04, (26, 3)).astype(np.float32)
    scene = SceneLookup(points)
    for z in (0.001, 0.002, 0.002):
        c = np.array([0, 0, 0.001, 0, 0, 0.001 - z], np.float32)
        kept = interval(table, 0.9, scene, c, 5e-4, 0.3, True)
        fresh = interval(table, 0.9, points, c, 5e-4, 0.3, True)
        np.testing.assert_array_equal(kept.radius, fresh.radius)
        assert kept.force == fresh.force
        d = path_distance(points.astype(np.float64), c[:3].astype(np.float64),
                          c[3:].astype(np.float64))
        np.testing.assert_array_equal(kept.radius, table.radii(level_index(0.9), d, z, 5e-4))
        assert not kept.radius.flags.writeable     # shared press after press: read-only


def test_a_thin_bin_takes_its_parents_radius() -> None:
    """Five scores of 100 in a depth bin of their own (the deepest presses) among 2000 of 1:
    too few for a quantile of their own, so their radius is their parent's (every depth at
    that distance), which the ones dominate."""
    n = 2000
    feats = np.column_stack([np.linspace(0, 0.04, n), np.full(n, 1e-3), np.zeros(n)])
    scores = np.ones(n)
    thin = np.arange(0, n, n // 5)[:5]
    feats[thin, 1], scores[thin] = 5e-3, 100.0
    bins = Bins.fit(scores, feats, ((0.25, 0.5, 0.75), (0.999,), (0.5,)))
    i = level_index(0.9)
    assert bins.widths(i, feats[thin, 0], 5e-3, 0.0) == pytest.approx(np.ones(5))
    assert (bins.count[..., i] >= MIN_COUNT).all()


def test_levels_refused_in_one_line() -> None:
    assert LEVELS[level_index(0.9)] == 0.9 and LEVELS[level_index(0.8)] == 0.8
    assert LEVELS[level_index(0.905)] == 0.91                 # the next level above
    for bad in (0.0, 1.0, -0.1, 1.5, float("nan"), "0.9", [0.9], np.array(0.9)):
        with pytest.raises(ValueError, match=r"level must lie in \(0, 1\)"):
            level_index(bad)
    with pytest.raises(ValueError, match="calibrated up to 0.99"):
        level_index(0.995)


def test_a_table_survives_json_with_an_unbounded_bin() -> None:
    rng = np.random.default_rng(2)
    scores, feats = _near_far(rng, 500)
    table = IntervalTable.fit(scores, feats, rng.uniform(0, 1, 10),
                              rng.uniform(0, 1e-3, (10, 2)), presses=2)
    assert np.isinf(table.force.width[..., level_index(0.95)]).all()   # 10 examples
    back = IntervalTable.from_dict(json.loads(json.dumps(table.to_dict(), allow_nan=False)))
    np.testing.assert_array_equal(back.points.width, table.points.width)
    np.testing.assert_array_equal(back.force.width, table.force.width)
    bad = table.to_dict()
    bad["points"]["width"] = bad["points"]["width"][:1]
    with pytest.raises(ValueError, match="shape"):
        IntervalTable.from_dict(bad)


def test_path_distance_is_euclidean() -> None:
    pts = np.array([[0.0, 0, 0], [1, 0, 0], [0, 0, 2], [3, 4, -1]])
    start, end = np.array([0.0, 0, 0]), np.array([0.0, 0, -1])
    np.testing.assert_allclose(path_distance(pts, start, end), [0, 1, 2, 5])
    np.testing.assert_allclose(path_distance(pts, start, start), [0, 1, 2, np.sqrt(26)])

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
    conformal_quantile,
    level_index,
    path_distance,
)

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
    for bad in (0.0, 1.0, -0.1, 1.5, float("nan"), "0.9"):
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

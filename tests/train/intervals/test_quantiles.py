"""The calibration's quantiles against known truth: exchangeable scores whose coverage is known
in closed form, bins that separate near and far points and the tip's own point, the fallback of
a thin bin."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.interval_table import near_far

from train.intervals.levels import level_index
from train.intervals.quantiles import MIN_COUNT, bin_edges, conformal_quantile
from train.intervals.table import Bins, IntervalTable
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


def test_bins_give_points_beside_the_tip_their_own_radius() -> None:
    rng = np.random.default_rng(0)
    scores, feats = near_far(rng, 8000)
    table = IntervalTable.fit(scores, feats, np.abs(rng.normal(0, 0.1, 400)),
                              rng.uniform(0, 1e-3, (400, 2)), presses=3)
    i = level_index(0.9)
    near = table.radii(i, np.array([0.001]), 1.5e-3, 5e-4)[0]
    far = table.radii(i, np.array([0.035]), 1.5e-3, 5e-4)[0]
    assert near == pytest.approx(Z90 * 1e-3, rel=0.15)      # the true 90 % radius there
    assert far == pytest.approx(Z90 * 1e-4, rel=0.15)
    # held-out scores drawn alike are covered at the level, near and far apart
    test, tf = near_far(np.random.default_rng(1), 20000)
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


def test_a_bins_intervals_nest_when_its_parent_takes_over_at_a_high_level() -> None:
    """A bin of 30 large scores (10-20) among 4000 small ones (0-1): its own quantile bounds
    it up to level 30/31, above which it takes its parent's, a small score; the interval at a
    higher level must still hold the lower one's."""
    depth = np.r_[np.full(30, 9e-3), np.linspace(1e-3, 2e-3, 4000)]
    scores = np.r_[np.linspace(10.0, 20.0, 30), np.linspace(0.0, 1.0, 4000)]
    bins = Bins.fit(scores, depth[:, None], ((0.995,),))
    deep = bins.width[-1]                                     # the bin of the 30 large scores
    assert deep[level_index(0.95)] == pytest.approx(20.0)     # its own quantile: the largest
    assert deep[level_index(0.97)] >= deep[level_index(0.95)]
    assert (np.diff(bins.width, axis=-1) >= 0).all()

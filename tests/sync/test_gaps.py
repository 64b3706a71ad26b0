"""Gap filling: short gaps interpolated smoothly, long and end gaps left missing and flagged."""

from __future__ import annotations

import numpy as np

from sync.gaps import FILLED, MISSING, fill_gaps, true_runs
from sync.sync_params import SyncParams

RATE = 500.0


def _track(n: int = 1000) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) / RATE
    x = np.stack([0.01 * np.sin(2 * np.pi * 1.3 * t), 0.005 * np.cos(2 * np.pi * 0.7 * t),
                  0.002 * t], axis=1)
    return t, np.stack([x, x + 0.02], axis=1)          # two points, (T, 2, 3)


def test_nan_runs() -> None:
    assert true_runs(np.array([0, 1, 1, 0, 1], bool)) == [(1, 3), (4, 5)]
    assert true_runs(np.zeros(3, bool)) == []


def test_short_gap_is_filled_close_to_the_truth() -> None:
    t, truth = _track()
    obs = truth.copy()
    obs[300:310, 0] = np.nan                           # 10 frames = 20 ms: filled
    filled, flags = fill_gaps(t, obs, max_gap_s=0.020)
    assert (flags[300:310, 0] == FILLED).all() and (flags[:, 1] == 0).all()
    assert flags[299, 0] == 0 and flags[310, 0] == 0
    np.testing.assert_allclose(filled[300:310, 0], truth[300:310, 0], atol=2e-6)
    np.testing.assert_array_equal(filled[~np.isnan(obs)], obs[~np.isnan(obs)])


def test_long_gap_and_end_gaps_stay_missing() -> None:
    t, truth = _track()
    obs = truth.copy()
    obs[400:411, 1] = np.nan                           # 11 frames = 22 ms: too long
    obs[:3, 0] = np.nan                                # at the start: nothing to interpolate from
    obs[-2:, 0] = np.nan
    filled, flags = fill_gaps(t, obs, max_gap_s=0.020)
    assert np.isnan(filled[400:411, 1]).all() and (flags[400:411, 1] == MISSING).all()
    assert (flags[:3, 0] == MISSING).all() and (flags[-2:, 0] == MISSING).all()
    assert np.isnan(filled[:3, 0]).all()


def test_point_missing_throughout_is_never_invented() -> None:
    t, truth = _track(200)
    obs = truth.copy()
    obs[:, 1] = np.nan
    filled, flags = fill_gaps(t, obs, max_gap_s=10.0)
    assert np.isnan(filled[:, 1]).all() and (flags[:, 1] == MISSING).all()


def test_fill_through_noisy_neighbours_stays_at_the_noise_level() -> None:
    rng = np.random.default_rng(0)
    t, truth = _track()
    errs = []
    for k in range(50):
        obs = truth + rng.normal(0, 0.2e-3, truth.shape)
        a = 100 + 15 * k
        obs[a:a + 10, 0] = np.nan
        filled, _ = fill_gaps(t, obs, SyncParams().max_gap_s)
        errs.append(filled[a:a + 10, 0] - truth[a:a + 10, 0])
    assert np.sqrt(np.mean(np.square(errs))) < 0.3e-3

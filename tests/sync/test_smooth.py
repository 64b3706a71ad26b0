"""Zero-phase smoothing of the tip track, run by run between gaps."""

from __future__ import annotations

import numpy as np

from sync.smooth import lowpass_track, smoothing_taps

RATE, CUTOFF = 500.0, 15.0
HALF = len(smoothing_taps(RATE, CUTOFF)) // 2


def test_motion_in_band_passes_without_delay() -> None:
    t = np.arange(2000) / RATE
    x = np.sin(2 * np.pi * 2.0 * t + 0.4)                 # a hand's 2 Hz, amplitude 1
    err = np.abs(lowpass_track(x, RATE, CUTOFF) - x)
    assert err[HALF:-HALF].max() < 1e-3                   # no lag, no loss inside
    assert err.max() < 1e-2                               # the ends bend it a little
    ramp = np.stack([0.02 * t, 1.0 - 0.5 * t], axis=1)
    np.testing.assert_allclose(lowpass_track(ramp, RATE, CUTOFF), ramp, atol=1e-12)


def test_noise_is_removed_at_the_ends_of_a_run_too() -> None:
    """White noise, 500 independent tracks side by side: the standard deviation of the
    output per sample, first and last samples included."""
    x = np.random.default_rng(0).normal(0.0, 1.0, (400, 500))
    sd = lowpass_track(x, RATE, CUTOFF).std(axis=1)
    inside = float(np.median(sd[HALF:-HALF]))
    assert 0.2 < inside < 0.35                          # 15 Hz of the 250 Hz band: ~0.27
    assert sd[0] < 0.55 and sd[-1] < 0.55               # not the raw sample (1.0)
    assert sd.max() < 2 * inside


def test_gaps_stay_gaps_and_short_runs_are_left_alone() -> None:
    rng = np.random.default_rng(1)
    x = rng.normal(0.0, 1.0, (1000, 3))
    x[300:320] = np.nan                                  # a gap
    x[320 + HALF : 330 + HALF] = np.nan                  # leaves a run of exactly HALF samples
    y = lowpass_track(x, RATE, CUTOFF)
    gaps = ~np.isfinite(x).all(axis=1)
    assert np.isnan(y[gaps]).all() and np.isfinite(y[~gaps]).all()
    np.testing.assert_array_equal(y[320 : 320 + HALF], x[320 : 320 + HALF])
    assert y[:300].std() < 0.5 and y[400:].std() < 0.5  # the long runs are smoothed
    # a run is filtered on its own: what lies across a gap does not leak into it
    z = x.copy()
    z[400:] += 100.0
    np.testing.assert_allclose(lowpass_track(z, RATE, CUTOFF)[:300], y[:300], atol=1e-12)


def test_off_returns_a_copy() -> None:
    x = np.random.default_rng(2).normal(size=(50, 3))
    for cutoff in (0.0, RATE / 4):
        y = lowpass_track(x, RATE, cutoff)
        np.testing.assert_array_equal(y, x)
        assert y is not x

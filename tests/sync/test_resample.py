"""Anti-aliased resampling: analytic sines, scipy's polyphase resampler, drifting time maps."""

from __future__ import annotations

import numpy as np
from scipy.signal import freqz, resample_poly

from sync.resample import antialias_taps, lowpass_zero_phase, resample_at
from sync.sync_params import SyncParams

FS_IN, FS_OUT = 1000.0, 500.0
PASSBAND = SyncParams().passband           # sync's resampler


def _sine(freq: float, n: int = 4000, phase: float = 0.3) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) / FS_IN
    return t, np.sin(2 * np.pi * freq * t + phase)


def test_filter_response_flat_in_band_and_stops_above_nyquist() -> None:
    taps = antialias_taps(FS_IN, FS_OUT, PASSBAND)
    assert len(taps) % 2 == 1
    np.testing.assert_allclose(taps, taps[::-1])          # symmetric: zero phase when centred
    w, h = freqz(taps, worN=4096, fs=FS_IN)
    gain = np.abs(h)
    assert np.all(np.abs(gain[w <= 200] - 1) < 1e-3)       # flat to 0.8 x output Nyquist
    assert np.all(gain[w >= 250] < 1.2e-4)                  # about 80 dB down at and above it


def test_sine_below_nyquist_is_kept_exactly_at_mocap_times() -> None:
    t, x = _sine(37.0)
    tq = np.arange(200, 1800) / FS_OUT                     # interior mocap frames
    y = resample_at(t, x, tq, FS_OUT, PASSBAND)
    np.testing.assert_allclose(y, np.sin(2 * np.pi * 37.0 * tq + 0.3), atol=2e-4)


def test_agrees_with_scipy_polyphase_on_the_integer_grid() -> None:
    t, x = _sine(60.0)
    ours = resample_at(t, x, t[::2], FS_OUT, PASSBAND)
    theirs = resample_poly(x, 1, 2)
    inner = slice(50, -50)
    np.testing.assert_allclose(ours[inner], theirs[inner], atol=2e-3)


def test_sine_above_nyquist_is_removed_not_aliased() -> None:
    t, x = _sine(310.0)                                    # aliases to 190 Hz at 500 Hz
    tq = t[200:-200:2]
    y = resample_at(t, x, tq, FS_OUT, PASSBAND)
    assert np.max(np.abs(y)) < 1e-3
    naive = x[200:-200:2]                                  # every other sample: full alias
    assert np.max(np.abs(naive)) > 0.9


def test_drifting_non_integer_time_map() -> None:
    """Mocap frames mapped into logger time: offset 0.37 ms, drift 50 ppm, 500 Hz."""
    t, x = _sine(23.0, n=20000)
    k = np.arange(500, 9500)
    tq = 0.01037 + (1 + 50e-6) * k / FS_OUT
    y = resample_at(t, x, tq, FS_OUT, PASSBAND)
    np.testing.assert_allclose(y, np.sin(2 * np.pi * 23.0 * tq + 0.3), atol=1e-4)


def test_queries_outside_the_log_are_nan_and_channels_work() -> None:
    t, x = _sine(5.0, n=1000)
    xx = np.stack([x, 2 * x, -x], axis=1)
    tq = np.array([-0.01, 0.5, 1.2])
    y = resample_at(t, xx, tq, FS_OUT, PASSBAND)
    assert y.shape == (3, 3)
    assert np.isnan(y[[0, 2]]).all()
    np.testing.assert_allclose(y[1], np.array([1, 2, -1]) * np.sin(2 * np.pi * 2.5 + 0.3),
                               rtol=1e-4)


def test_zero_phase_keeps_a_pulse_centred_and_a_ramp_at_the_ends() -> None:
    taps = antialias_taps(FS_IN, FS_OUT, PASSBAND)
    n = np.arange(1000)
    pulse = np.exp(-0.5 * ((n - 400.0) / 6.0) ** 2)
    y = lowpass_zero_phase(pulse, taps)
    assert int(np.argmax(y)) == 400
    ramp = 0.002 * n + 1.0                                 # odd reflection keeps a ramp exact
    np.testing.assert_allclose(lowpass_zero_phase(ramp, taps), ramp, atol=1e-9)

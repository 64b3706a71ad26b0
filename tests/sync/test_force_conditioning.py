"""The force log made ready to resample (:mod:`sync.force_conditioning`), on hand-built logs
whose truth is known: the amplifier's rails from the .cal, samples on a rail or in a flat top,
the force beyond the rating without a calibration, which frames a flagged sample reaches, the
rest after the first press, the log's clock, and the tare, calibration and re-tare of a log
whose bias and creep are set here.

Whole sessions with clipped gauges, a quantised quiet log and an over-range press are
``test_sync_extremes.py``'s; the rating's limits themselves are ``tests/test_extremes.py``'s.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from calib.force_tare import Tare
from core.errors import BadInput
from core.series import AtiCalibration, ForceSeries
from sync.force_conditioning import (
    FLAT_RUN,
    FLAT_SIGMAS,
    RAIL_TOLERANCE,
    beyond_rating,
    condition_force,
    force_times,
    near_samples,
    noise_level,
    on_rail,
    output_rails,
    quantisation_step,
    rest_after_first_press,
    tare_and_calibrate,
)
from sync.sync_params import SyncParams

RATE = 1000.0
NANO17_MAX = np.array([25.0, 25.0, 35.0, 0.25, 0.25, 0.25])


def _cal(matrix: np.ndarray | None = None, **calibration: str) -> AtiCalibration:
    """An ATI calibration whose .cal states ``calibration`` (OutputRange, OutputBipolar)."""
    return AtiCalibration("FT1.cal", "FT1", "Nano17", "SI-25-0.25",
                          np.eye(6) if matrix is None else matrix, NANO17_MAX, "N", "N-m",
                          {"calibration": dict(calibration)})


def _raw(values: np.ndarray, kind: str = "gauge", cal: AtiCalibration | None = None,
         time_ns: np.ndarray | None = None) -> SimpleNamespace:
    """A session's force log (what these functions read of a RawSession)."""
    t = np.arange(len(values), dtype=np.int64) * 1_000_000 if time_ns is None else time_ns
    units = ["V"] * 6 if kind == "gauge" else ["N"] * 3 + ["N*m"] * 3
    force = ForceSeries("force.csv", t, [f"G{i}" for i in range(6)], values, units, kind, RATE)
    return SimpleNamespace(force=force, calibration=cal)


def _noise(n: int, sd: float, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(0.0, sd, (n, 6))


# --- the amplifier's rails -------------------------------------------------------------------

@pytest.mark.parametrize(("calibration", "rails"), [
    ({"OutputRange": "20", "OutputBipolar": "True"}, (-10.0, 10.0)),
    ({"OutputRange": "20"}, (-10.0, 10.0)),              # bipolar unless it says not
    ({"OutputRange": "10", "OutputBipolar": "False"}, (0.0, 10.0)),
    ({"OutputRange": "10", "OutputBipolar": " false "}, (0.0, 10.0)),
    ({"OutputRange": "5.0", "OutputBipolar": "true"}, (-2.5, 2.5)),
    ({}, None), ({"OutputRange": "wide"}, None), ({"OutputRange": "0"}, None),
    ({"OutputRange": "-20"}, None), ({"OutputRange": "nan"}, None),
])
def test_the_output_range_of_the_cal_gives_the_rails(calibration: dict, rails) -> None:
    """OutputRange and OutputBipolar as an ATI .cal writes them; a range that is missing, not a
    number or not positive gives no rails."""
    assert output_rails(_raw(np.zeros((10, 6)), cal=_cal(**calibration))) == rails


def test_a_wrench_log_or_one_without_a_cal_has_no_rails() -> None:
    """Rails are a gauge amplifier's: none for a wrench log or without a .cal."""
    assert output_rails(_raw(np.zeros((10, 6)), "wrench", _cal(OutputRange="20"))) is None
    assert output_rails(_raw(np.zeros((10, 6)))) is None


def test_samples_within_half_a_percent_of_a_rail_are_flagged() -> None:
    """+-10 V: within 0.005 x 20 V = 0.1 V of either end, on any channel. 9.95 V and -9.92 V
    are on a rail, 9.85 V is not (one sample of each: no flat top)."""
    assert RAIL_TOLERANCE == 0.005
    v = _noise(2000, 1e-3)
    v[100, 2], v[200, 4], v[300, 0], v[400, 1] = 9.95, -9.92, 9.85, 9.9
    flagged = on_rail(_raw(v, cal=_cal(OutputRange="20", OutputBipolar="True")))
    assert np.flatnonzero(flagged).tolist() == [100, 200, 400]


def test_a_unipolar_amplifier_s_rails_are_zero_and_its_range() -> None:
    """0..10 V around a 5 V rest: 9.96 V and 0.02 V are on its rails, 5 V is not."""
    v = 5.0 + _noise(2000, 1e-3)
    v[500, 3], v[700, 5] = 9.96, 0.02
    flagged = on_rail(_raw(v, cal=_cal(OutputRange="10", OutputBipolar="False")))
    assert np.flatnonzero(flagged).tolist() == [500, 700]


def test_a_flat_top_far_from_the_channel_s_median_is_a_clip() -> None:
    """No range in the .cal; noise 1 mV. Eight samples at exactly +0.5 V (channel 0's highest
    value, 500 noise widths up) and eight at exactly -0.4 V (channel 3's lowest) are clipped;
    seven in a row on channel 1 are not yet a flat top; eight at channel 2's highest but only
    10 noise widths up (below FLAT_SIGMAS) are a quiet channel's peak, not a clip."""
    assert (FLAT_RUN, FLAT_SIGMAS) == (8, 20.0)
    v = _noise(3000, 1e-3)
    v[1000:1008, 0] = 0.5
    v[2000:2008, 3] = -0.4
    v[500:507, 1] = 0.5
    v[1500:1508, 2] = 0.01
    flagged = on_rail(_raw(v, cal=_cal()))
    assert np.flatnonzero(flagged).tolist() == [*range(1000, 1008), *range(2000, 2008)]


def test_a_wrench_log_is_never_on_a_rail() -> None:
    """Already in newtons: its limit is the rated load (``beyond_rating``), not a voltage."""
    v = _noise(2000, 1e-3)
    v[100:120, 2] = 10.0
    assert not on_rail(_raw(v, "wrench", _cal(OutputRange="20"))).any()


def test_without_a_calibration_nothing_is_over_range() -> None:
    """A wrench log whose rating is unknown: no sample can be said to exceed it."""
    sampled = np.full((5, 6), 1e3)
    out = beyond_rating(sampled, _raw(np.zeros((5, 6)), "wrench").calibration)
    assert out.shape == (5,) and not out.any()


@pytest.mark.parametrize(("values", "step"), [
    ([0.0, 0.5, 1.5, 1.5, 0.5], 0.5), ([3.0, 3.0, 3.0], 0.0), ([0.001, 0.004, 0.002], 0.001),
])
def test_the_quantisation_step_is_the_smallest_difference_of_distinct_values(values, step
                                                                            ) -> None:
    """Repeats do not count; a constant channel has step 0."""
    assert quantisation_step(np.array(values)) == pytest.approx(step, abs=1e-15)


# --- which frames a flagged sample reaches ---------------------------------------------------

def test_queries_within_reach_of_a_flagged_sample_are_flagged() -> None:
    """Samples at 1.0 s and 2.0 s flagged, reach 0.1 s: queries 0.95, 1.05, 1.1 (at the reach)
    and 2.1 are near one; 0.5, 1.5, 1.11, 2.2 and NaN are not."""
    t = np.arange(0.0, 3.0, 0.01)
    flagged = np.isclose(t, 1.0) | np.isclose(t, 2.0)
    q = np.array([0.5, 0.95, 1.05, 1.1, 1.11, 1.5, 2.1, 2.2, np.nan])
    out = near_samples(t, flagged, q, 0.1 + 1e-12)
    assert out.tolist() == [False, True, True, True, False, False, True, False, False]


def test_one_or_no_flagged_sample() -> None:
    """No flagged sample reaches nothing; a single one reaches its neighbourhood."""
    t = np.arange(0.0, 1.0, 0.01)
    q = np.array([0.0, 0.48, 0.52, 0.9])
    assert not near_samples(t, np.zeros(len(t), bool), q, 0.1).any()
    one = np.isclose(t, 0.5)
    assert near_samples(t, one, q, 0.05).tolist() == [False, True, True, False]


# --- the rest after the first press ----------------------------------------------------------

def test_the_rest_after_the_first_press_is_the_median_until_the_next() -> None:
    """detect 1 N: the first press rises at sample 2, is released at sample 5 (below 0.5 N),
    the next rises at 9: the rest is the median of samples 5..8 = 0.2 N."""
    m = np.array([0.0, 0.0, 2.0, 3.0, 0.8, 0.1, 0.2, 0.3, 0.2, 2.0, 0.0])
    assert rest_after_first_press(m, 1.0) == pytest.approx(0.2)


def test_the_rest_lasts_to_the_end_without_another_press() -> None:
    """One press: the rest runs from its release to the end of the log."""
    m = np.array([0.0, 2.0, 0.4, 0.1, 0.3, 0.1])
    assert rest_after_first_press(m, 1.0) == pytest.approx(np.median([0.4, 0.1, 0.3, 0.1]))


@pytest.mark.parametrize("m", [[0.0, 0.5, 0.9, 0.2], [0.0, 2.0, 1.5, 0.6]])
def test_no_rest_without_a_press_or_a_release(m: list) -> None:
    """Nothing above 1 N; or a press that never falls below 0.5 N."""
    assert rest_after_first_press(np.array(m), 1.0) is None


# --- the log's clock and noise ---------------------------------------------------------------

def test_force_times_are_the_stamps_in_seconds() -> None:
    """int64 ns stamps (from a logger's epoch) in float seconds, exact to the ns; no hole."""
    raw = _raw(np.zeros((100, 6)), time_ns=5_000_000_000 + np.arange(100) * 1_000_000)
    t, timing = force_times(raw)
    np.testing.assert_allclose(t, 5.0 + np.arange(100) * 1e-3, rtol=0, atol=1e-12)
    assert timing.period_ns == 1_000_000 and timing.holes == ()


def test_a_jittered_or_short_log_is_refused_and_a_hole_is_found() -> None:
    """One step 0.2 ms long in a 1 kHz log (20 % of a step, more than 10 %): jitter, named
    with its sample; 0.15 ms still; 0.05 ms (5 %) is a uniform log. A step of 51 ms is a hole
    of 50 lost samples, not jitter. 63 samples are too few."""
    t = np.arange(200, dtype=np.int64) * 1_000_000
    t[100:] += 200_000
    with pytest.raises(BadInput) as e:
        force_times(_raw(np.zeros((200, 6)), time_ns=t))
    assert e.value.path == "force.csv" and e.value.where == "sample 100"
    assert "not evenly spaced: a step of 1.200 ms where the period is 1.000 ms" \
        in e.value.what
    t[100:] -= 50_000                                   # 0.15 ms: 15 %, still refused
    with pytest.raises(BadInput):
        force_times(_raw(np.zeros((200, 6)), time_ns=t))
    t[100:] -= 100_000                                  # 0.05 ms: 5 %, a uniform log
    assert len(force_times(_raw(np.zeros((200, 6)), time_ns=t))[0]) == 200
    t = np.arange(200, dtype=np.int64) * 1_000_000
    t[100:] += 50_000_000
    (hole,) = force_times(_raw(np.zeros((200, 6)), time_ns=t))[1].holes
    assert (hole.index, hole.lost, hole.length_s) == (100, 50, pytest.approx(0.050))
    with pytest.raises(BadInput, match="too short"):
        force_times(_raw(np.zeros((63, 6))))


def test_the_noise_is_the_widest_force_component_while_unloaded() -> None:
    """Components alternating +-1, +-2 and 0 mN over the unloaded interval (std 1, 2, 0 mN),
    a torque of +-10 (not a force), and a press after it: 2 mN."""
    w = np.zeros((300, 6))
    sign = np.where(np.arange(100) % 2, 1.0, -1.0)
    w[:100, 0], w[:100, 1], w[:100, 3] = 1e-3 * sign, 2e-3 * sign, 10.0 * sign
    w[100:, 2] = 5.0
    tare = Tare(np.zeros(6), np.zeros(6), 0, 100)
    assert noise_level(w, tare) == pytest.approx(2e-3, rel=1e-12)


# --- tare, calibration and re-tare -----------------------------------------------------------

def _presses(t: np.ndarray, starts: list[float], peak: float) -> np.ndarray:
    """Fz (N): a ``peak`` N sin^2 press of 2 s from each start."""
    f = np.zeros(len(t))
    for a in starts:
        s = (t - a) / 2.0
        inside = (s >= 0) & (s <= 1)
        f[inside] += peak * np.sin(np.pi * s[inside]) ** 2
    return f


def test_gauge_volts_are_tared_and_calibrated_into_the_true_wrench() -> None:
    """Volts = bias + M^-1 wrench + 2 uV noise, M a full 6 x 6 matrix: the start's bias is
    taken off and M applied, giving the true wrench (presses of 5 N along z) within 1 mN."""
    t = np.arange(int(12 * RATE)) / RATE
    truth = np.zeros((len(t), 6))
    truth[:, 2] = _presses(t, [2.0, 6.0], 5.0)
    truth[:, 0] = 0.1 * truth[:, 2]
    rng = np.random.default_rng(1)
    matrix = np.diag([20.0, 20.0, 40.0, 0.5, 0.5, 0.5]) + rng.normal(0, 0.5, (6, 6))
    bias = np.array([0.3, -0.2, 1.1, 0.05, -0.4, 0.2])
    volts = bias + truth @ np.linalg.inv(matrix).T + rng.normal(0, 2e-6, truth.shape)
    tare, wrench, noise = tare_and_calibrate(_raw(volts, cal=_cal(matrix)), SyncParams())
    np.testing.assert_allclose(tare.bias, bias, atol=1e-5)
    np.testing.assert_allclose(wrench[:, :3], truth[:, :3], atol=1e-3)
    assert tare.start == 0 and tare.stop >= 0.2 * RATE
    assert 0 < noise < 2e-3


def test_gauge_volts_without_a_calibration_are_refused() -> None:
    """Volts cannot become newtons without the ATI matrix."""
    with pytest.raises(BadInput) as e:
        tare_and_calibrate(_raw(_noise(2000, 1e-3)), SyncParams())
    assert e.value.path == "force.csv"
    assert e.value.what == "gauge voltages but no ATI calibration in the session"


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_a_missing_sample_is_refused_naming_the_first(bad: float) -> None:
    """A NaN or inf sample: refused at the first one's index (not a later one)."""
    v = _noise(2000, 1e-3)
    v[1234, 4] = bad
    v[1500, 0] = bad
    with pytest.raises(BadInput) as e:
        tare_and_calibrate(_raw(v, "wrench"), SyncParams())
    assert e.value.where == "sample 1234" and "missing samples" in e.value.what


def test_the_re_tare_takes_the_creep_off_between_presses() -> None:
    """A wrench log with a bias of 0.2 N on Fz and three 4 N presses, each leaving the bias
    20 mN higher (creeping up over the press): with the re-tare the force between the
    presses is 0 within 3 mN and the peaks the true 4 N within 10 mN; without it the creep
    (20, 40, 60 mN) stays between them."""
    t = np.arange(int(16 * RATE)) / RATE
    starts = [2.0, 6.0, 10.0]
    truth = _presses(t, starts, 4.0)
    creep = 0.02 * sum(np.clip((t - a) / 2.0, 0.0, 1.0) for a in starts)
    w = np.zeros((len(t), 6))
    w[:, 2] = 0.2 + creep + truth
    w += _noise(len(t), 5e-4, seed=3)
    raw = _raw(w, "wrench")
    rest = (t > 4.5) & (t < 5.5) | (t > 8.5) & (t < 9.5) | (t > 12.5)
    peaks = np.array([np.argmin(np.abs(t - a - 1.0)) for a in starts])
    on = condition_force(raw, SyncParams())
    assert on.rest.time_s.size > 0
    assert np.abs(on.wrench[rest, 2]).max() < 3e-3
    np.testing.assert_allclose(on.wrench[peaks, 2], truth[peaks], atol=10e-3)
    off = condition_force(raw, SyncParams(retare=False))
    assert off.rest.time_s.size == 0
    np.testing.assert_allclose(off.wrench[rest, 2], creep[rest], atol=3e-3)
    assert np.abs(off.wrench[rest & (t > 12.5), 2] - 0.06).max() < 3e-3
    np.testing.assert_allclose(off.time_s, t, atol=1e-12)
    assert on.contact == off.contact == max(0.05, 5 * on.noise)

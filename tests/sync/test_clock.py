"""Clock offset and drift: trigger pulses and the data-driven estimate against known clocks."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import BadInput
from sync.clock import (
    ClockFit,
    clock_from_data,
    contact_lags,
    fit_offsets,
    match_trigger,
    rising_edges,
)
from sync.resample import antialiased_interpolant
from sync.sync_params import SyncParams

OFFSET, DRIFT = 1.23456, 37.0          # s, ppm: t_f = OFFSET + (1 + DRIFT e-6) t_m


def _to_logger(t_m: np.ndarray) -> np.ndarray:
    return OFFSET + (1 + DRIFT * 1e-6) * t_m


def test_fit_offsets_matches_numpy_polyfit() -> None:
    rng = np.random.default_rng(0)
    x = np.sort(rng.uniform(0, 100, 40))
    y = 0.5 + 20e-6 * x + rng.normal(0, 1e-4, 40)
    fit = fit_offsets(x, y, "trigger")
    coef, cov = np.polyfit(x, y, 1, cov=True)
    assert fit.offset_s == pytest.approx(coef[1], abs=1e-12)
    assert fit.drift_ppm == pytest.approx(coef[0] * 1e6, abs=1e-9)
    assert fit.offset_sd_s == pytest.approx(np.sqrt(cov[1, 1]), rel=1e-6)
    assert fit.drift_sd_ppm == pytest.approx(np.sqrt(cov[0, 0]) * 1e6, rel=1e-6)
    np.testing.assert_allclose(fit.to_mocap(fit.to_logger(x)), x, atol=1e-12)


def test_rising_edges_of_a_slewed_ttl_are_sub_sample() -> None:
    """A 0/5 V pulse train with a 3 ms linear slew, sampled at 1 kHz."""
    edges = np.array([0.1003, 0.4117, 0.8871, 1.2345])
    t = np.arange(0, 1.5, 1e-3)
    v = np.zeros_like(t)
    for e in edges:
        v += 5 * np.clip((t - e) / 3e-3 + 0.5, 0, 1) * (t < e + 0.05)
    got = rising_edges(t, v)
    np.testing.assert_allclose(got, edges, atol=1e-9)


def _pulses(seed: int, n: int = 60) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.uniform(0.5, 1.5, n))          # irregular intervals, mocap time


def test_trigger_matching_with_missing_and_extra_pulses() -> None:
    rng = np.random.default_rng(1)
    events = _pulses(1)
    edges = _to_logger(events) + rng.uniform(-5e-4, 5e-4, len(events))   # 1 kHz edge jitter
    edges = np.delete(edges, [0, 1, 17])                                  # logger started late
    events = np.delete(events, [40])                                      # a dropped event
    edges = np.sort(np.append(edges, edges[-1] + 0.7))                   # one extra edge
    fit = match_trigger(edges, events, source="force.csv")
    assert fit.method == "trigger" and fit.n == len(events) - 3
    assert abs(fit.offset_s - OFFSET) < 3e-4
    assert abs(fit.drift_ppm - DRIFT) < 5
    assert abs(fit.offset_s - OFFSET) < 4 * fit.offset_sd_s
    assert abs(fit.drift_ppm - DRIFT) < 4 * fit.drift_sd_ppm


def test_trigger_matching_scales_to_a_long_session() -> None:
    """1,200 pulses (half an hour): every (edge, event) pair is a proposal, 1.4 million of
    them, counted at once (a loop over proposals took seconds; timed in bench_sync.py)."""
    rng = np.random.default_rng(5)
    events = np.cumsum(rng.uniform(0.7, 2.3, 1200))
    edges = _to_logger(events) + rng.uniform(-5e-4, 5e-4, len(events))
    edges = np.delete(edges, np.arange(0, 1200, 97))                      # missed edges
    fit = match_trigger(edges, events, source="force.csv")      # its time: bench_sync.py
    assert fit.n == len(edges)
    assert abs(fit.offset_s - OFFSET) < 1e-4 and abs(fit.drift_ppm - DRIFT) < 0.5


def test_periodic_trigger_needs_a_prior() -> None:
    events = np.arange(1, 40) * 1.0
    edges = _to_logger(events[3:30])
    with pytest.raises(BadInput, match="ambiguous"):
        match_trigger(edges, events, source="force.csv")
    prior = ClockFit(OFFSET + 0.2, 0.0, 0.1, 100.0, 0.0, 1, "data")
    fit = match_trigger(edges, events, prior=prior)
    assert abs(fit.offset_s - OFFSET) < 1e-6


def test_unrelated_pulses_are_refused() -> None:
    with pytest.raises(BadInput, match=r"force\.csv: trigger: .*do not match"):
        match_trigger(_pulses(2, 20), _pulses(3, 20) + 1000.0, source="force.csv")


def _session(seed: int, presses: int = 6, depth_noise: float = 0.2e-3
             ) -> dict[str, np.ndarray]:
    """Mocap depth at 500 Hz and the force it causes, logged at 1 kHz on the drifting clock."""
    rng = np.random.default_rng(seed)
    t_m = np.arange(0, 4.0 * presses + 2, 1 / 500)
    depth = np.full_like(t_m, -0.02)
    for k in range(presses):
        start, rise, hold, fall = 1 + 4 * k, rng.uniform(0.6, 1.2), rng.uniform(0, .5), \
            rng.uniform(0.8, 1.5)
        peak = rng.uniform(0.004, 0.009)
        s = (t_m - start) / rise
        up = (s >= 0) & (s < 1)
        depth[up] = -0.02 + (peak + 0.02) * 0.5 * (1 - np.cos(np.pi * s[up]))
        h = (t_m >= start + rise) & (t_m < start + rise + hold)
        depth[h] = peak
        s2 = (t_m - start - rise - hold) / fall
        dn = (s2 >= 0) & (s2 < 1)
        depth[dn] = peak - (peak + 0.02) * 0.5 * (1 - np.cos(np.pi * s2[dn]))

    def force_of(t):
        d = np.interp(t, t_m, depth)
        return 7.0 * (np.clip(d, 0, None) / 0.008) ** 1.5

    t_f = np.arange(0.2, _to_logger(t_m[-1]) + 0.3, 1e-3)
    force = force_of((t_f - OFFSET) / (1 + DRIFT * 1e-6)) + rng.normal(0, 0.01, len(t_f))
    depth_obs = depth + rng.normal(0, depth_noise, len(t_m))
    return {"t_m": t_m, "depth": depth_obs, "t_f": t_f, "force": force}


def _data_fit(s: dict[str, np.ndarray]) -> ClockFit:
    force_at = antialiased_interpolant(s["t_f"], s["force"], 500.0, SyncParams().passband)
    lag0 = contact_lags(s["t_m"], s["depth"], force_at, (s["t_f"][0], s["t_f"][-1]),
                        max_lag_s=5.0)[0][0]
    assert abs(lag0 - (OFFSET + DRIFT * 1e-6 * s["t_m"].mean())) < 0.02
    loaded = force_at(s["t_m"] + lag0) > 0.3
    runs = np.flatnonzero(np.diff(loaded.astype(int)))
    presses = [(s["t_m"][a:b], s["depth"][a:b]) for a, b in zip(runs[::2] + 1, runs[1::2] + 1,
                                                                 strict=True)]
    return clock_from_data(presses, force_at, lag0)


@pytest.mark.parametrize("seed", [0, 1])
def test_data_driven_clock_is_exact_with_clean_motion(seed: int) -> None:
    """Noise-free depth: only the force noise and the polynomial law limit the estimate."""
    fit = _data_fit(_session(seed, depth_noise=0.0))
    assert fit.method == "data" and fit.n == 6
    assert abs(fit.offset_s - OFFSET) < 0.1e-3
    assert abs(fit.drift_ppm - DRIFT) < 5.0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_data_driven_clock_reports_honest_uncertainty(seed: int) -> None:
    """0.2 mm depth noise: the errors stay within the reported standard errors."""
    fit = _data_fit(_session(seed))
    assert fit.n == 6
    assert abs(fit.offset_s - OFFSET) < 4 * fit.offset_sd_s
    assert abs(fit.drift_ppm - DRIFT) < 4 * fit.drift_sd_ppm
    assert fit.offset_sd_s < 1.5e-3


def test_data_driven_clock_walks_from_a_poor_seed() -> None:
    """A seed lag 0.12 s off (more than twice the scan's reach, inside the cost's basin,
    which is a few tenths of the press's rise time wide): each press's scan moves on."""
    s = _session(3, depth_noise=0.0)
    force_at = antialiased_interpolant(s["t_f"], s["force"], 500.0, SyncParams().passband)
    lag = OFFSET + DRIFT * 1e-6 * s["t_m"].mean()
    loaded = force_at(s["t_m"] + lag) > 0.3
    runs = np.flatnonzero(np.diff(loaded.astype(int)))
    presses = [(s["t_m"][a:b], s["depth"][a:b]) for a, b in zip(runs[::2] + 1, runs[1::2] + 1,
                                                                 strict=True)]
    fit = clock_from_data(presses, force_at, lag - 0.12)
    assert fit.n == 6 and abs(fit.offset_s - OFFSET) < 0.1e-3


def test_data_driven_without_tracked_presses_is_bad_input() -> None:
    s = _session(0, presses=2)
    force_at = antialiased_interpolant(s["t_f"], s["force"], 500.0, SyncParams().passband)
    presses = [(s["t_m"][:10], s["depth"][:10] * np.nan)]
    with pytest.raises(BadInput, match="trial.tsv: clock"):
        clock_from_data(presses, force_at, OFFSET, source="trial.tsv")

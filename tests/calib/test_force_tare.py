"""Force tare (bias from the unloaded start) and the 6x6 calibration matrix."""

from __future__ import annotations

import numpy as np
import pytest

from calib.force_tare import apply_calibration, noise_sigma, rest_baseline, unloaded_start
from core.errors import BadInput

RATE = 1000.0


def _log(seed: int, load_at: float = 1.5, n: int = 4000, quantum: float = 0.0
         ) -> tuple[np.ndarray, np.ndarray]:
    """Six gauge channels: bias + noise, then a smooth load from ``load_at`` seconds."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE
    bias = rng.uniform(-0.5, 0.5, 6)
    load = np.clip((t - load_at) / 0.5, 0, None)[:, None] ** 2 * rng.uniform(0.05, 0.2, 6)
    v = bias + load + rng.normal(0, 2e-3, (n, 6))
    if quantum:
        v = np.round(v / quantum) * quantum
    return v, bias


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_bias_from_the_unloaded_start(seed: int) -> None:
    v, bias = _log(seed)
    tare = unloaded_start(v, RATE, max_s=5.0)
    assert 1.2 * RATE < tare.stop <= 1.75 * RATE      # stops once the load leaves the noise
    np.testing.assert_allclose(tare.bias, bias, atol=4 * 2e-3 / np.sqrt(tare.stop))
    np.testing.assert_allclose(tare.noise, 2e-3, rtol=0.15)


def test_quantised_quiet_channel_still_tares() -> None:
    v, bias = _log(3, quantum=5e-3)
    tare = unloaded_start(v, RATE)
    np.testing.assert_allclose(tare.bias, bias, atol=2e-3)
    assert tare.stop >= 1.2 * RATE


def test_noise_sigma_of_white_noise() -> None:
    x = np.random.default_rng(4).normal(0, 0.3, (20000, 2))
    np.testing.assert_allclose(noise_sigma(x), 0.3, rtol=0.03)


def test_log_starting_during_a_press_is_refused() -> None:
    v, _ = _log(5, load_at=-0.2)                       # already loading at the first sample
    with pytest.raises(BadInput, match=r"force\.csv:sample 0: .*no unloaded interval"):
        unloaded_start(v, RATE, source="force.csv")


def test_load_too_soon_is_refused() -> None:
    v, _ = _log(6, load_at=0.11)
    with pytest.raises(BadInput, match="unloaded start of at least"):
        unloaded_start(v, RATE, source="force.csv")


def test_calibration_matrix_and_bias() -> None:
    rng = np.random.default_rng(7)
    c = rng.normal(0, 1, (6, 6))
    bias = rng.normal(0, 1, 6)
    v = rng.normal(0, 1, (10, 6))
    w = apply_calibration(v, bias, c)
    np.testing.assert_allclose(w, np.array([c @ (row - bias) for row in v]), atol=1e-12)
    np.testing.assert_allclose(apply_calibration(v, bias), v - bias)


def _pressing(seed: int, press_s: float, cycle_s: float, n: int, creep: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A tared force log (T, 6): ``n`` sin^2 presses of 6 N along z lasting ``press_s``, one
    every ``cycle_s``, on a rest level that creeps linearly (``creep`` per second) and steps
    by a few mN in every gap (the tool's weight as the hand turns). Returns time, log, true
    force and true rest level."""
    rng = np.random.default_rng(seed)
    t = np.arange(0, n * cycle_s + 2.0, 1 / RATE)
    force = np.zeros((len(t), 6))
    step = np.zeros((len(t), 6))
    for k in range(n):
        on = 1.0 + k * cycle_s + 0.5 * (cycle_s - press_s)
        u = (t - on) / press_s
        inside = (u >= 0) & (u <= 1)
        force[inside, 2] = 6.0 * np.sin(np.pi * u[inside]) ** 2
        step[t >= on - 0.3 * (cycle_s - press_s), :3] = rng.uniform(-4e-3, 4e-3, 3)
    rest = np.outer(t, creep) + step
    log = force + rest + rng.normal(0, 3e-3, force.shape)
    return t, log, force, rest


def test_re_tare_follows_bias_creep_and_tool_weight() -> None:
    creep = np.array([0.1, -0.2, 0.3, 0.0, 0.0, 0.0]) * 1e-3          # 0.3 mN/s on Fz
    t, log, force, rest = _pressing(0, 2.0, 6.0, 60, creep)            # 6 minutes
    assert np.abs(rest[:, 2]).max() > 0.1                              # 5x the force target
    base = rest_baseline(t, log, contact_n=0.05, coarse_n=0.25)
    err = np.linalg.norm((log - base.at(t) - force)[:, :3], axis=1)
    loaded = force[:, 2] > 0.05
    assert np.sqrt(np.mean(err[loaded] ** 2)) < 6e-3                   # the noise: 5.2 mN
    near = base.at(t)[:, :3] - rest[:, :3]
    assert np.abs(near[loaded]).mean() < 1e-3


def test_re_tare_ignores_the_soft_start_of_a_slow_press() -> None:
    """A 40 s press stays below the contact level for 1.2 s at each end; those frames
    must not count as rest."""
    t, log, force, rest = _pressing(1, 40.0, 60.0, 3, np.zeros(6))
    base = rest_baseline(t, log, contact_n=0.05, coarse_n=0.25)
    loaded = force[:, 2] > 0.05
    np.testing.assert_allclose(base.at(t)[loaded, :3], rest[loaded, :3], atol=1.5e-3)


def test_re_tare_without_rest_is_zero() -> None:
    t = np.arange(1000) / RATE
    log = np.zeros((1000, 6))
    log[:, 2] = 1.0                                                     # loaded throughout
    base = rest_baseline(t, log, contact_n=0.05, coarse_n=0.25)
    assert len(base.time_s) == 0 and not base.at(t).any()

"""Force tare (bias from the unloaded start) and the 6x6 calibration matrix."""

from __future__ import annotations

import numpy as np
import pytest

from calib.force import apply_calibration, noise_sigma, unloaded_start
from pipeline.errors import BadInput

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

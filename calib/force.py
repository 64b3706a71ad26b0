"""Force-sensor tare and calibration: raw log to the wrench in the sensor frame.

The bias is the mean of the unloaded start of the recording: the longest stretch from the first
sample over which every channel stays within a few noise widths of its starting level. A log
that starts loaded (or moving) has no such stretch and is refused, since any bias taken from it
would be wrong by the load.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.errors import BadInput


@dataclass
class Tare:
    """The bias and the unloaded interval it came from."""

    bias: np.ndarray      # (C,) in the channels' units
    noise: np.ndarray     # (C,) standard deviation of the channels while unloaded
    start: int            # first sample of the unloaded interval (always 0)
    stop: int             # one past its last sample


def noise_sigma(x: np.ndarray) -> np.ndarray:
    """Robust white-noise standard deviation per column, from first differences (MAD).

    Never below the rounding noise of the column's quantisation step (its smallest non-zero
    difference over sqrt(12)), so a quantised, nearly noiseless channel still gets a width.
    """
    d = np.diff(np.asarray(x, float), axis=0)
    mad = np.median(np.abs(d - np.median(d, axis=0)), axis=0)
    nz = np.where(d != 0, np.abs(d), np.inf).min(axis=0)
    quantum = np.where(np.isfinite(nz), nz, 0.0) / np.sqrt(12.0)
    return np.maximum(1.4826 * mad / np.sqrt(2.0), quantum)


def unloaded_start(
    values: np.ndarray,
    rate_hz: float,
    source: str | Path | None = None,
    probe_s: float = 0.1,
    min_s: float = 0.2,
    max_s: float = 2.0,
    k_sigma: float = 6.0,
    floor: np.ndarray | float = 1e-12,
) -> Tare:
    """Find the unloaded start of a (T, C) log and its bias.

    The first ``probe_s`` seconds give a level and a noise width per channel; the interval
    extends while every channel stays within ``k_sigma`` widths (at least ``floor``) of that
    level, up to ``max_s``, and is then cut back to where a short moving average first leaves
    its own noise band (so the start of a slow load does not bias the tare). The probe itself
    must be flat (no trend beyond the noise), and the interval must last ``min_s``; otherwise
    :class:`BadInput` names ``source``.
    """
    x = np.asarray(values, float)
    n_probe = max(int(round(probe_s * rate_hz)), 8)
    if len(x) < n_probe or not np.isfinite(x[:n_probe]).all():
        raise BadInput(source, "force log too short or not finite at its start: "
                               "no unloaded interval to tare from")
    probe = x[:n_probe]
    sig_diff = np.maximum(noise_sigma(probe), floor)
    tt = np.arange(n_probe) - (n_probe - 1) / 2
    slope = tt @ (probe - probe.mean(axis=0)) / (tt @ tt)
    trend = np.abs(slope) * n_probe
    if (trend > k_sigma * sig_diff).any():
        raise BadInput(source, "force log does not start unloaded (its first "
                               f"{probe_s * 1e3:.0f} ms drift by up to "
                               f"{np.max(trend / sig_diff):.0f} noise widths): no unloaded "
                               "interval to tare from", where="sample 0")
    sigma = np.maximum(sig_diff, (probe - probe.mean(axis=0) - np.outer(tt, slope)).std(axis=0))
    limit = min(max(int(round(max_s * rate_hz)), n_probe), len(x))
    head = x[:limit]
    away = (np.abs(head - np.median(probe, axis=0)) > k_sigma * sigma).any(axis=1)
    away |= ~np.isfinite(head).all(axis=1)
    stop = int(np.argmax(away)) if away.any() else limit
    for _ in range(2):                 # the level from the interval, the interval from the level
        if stop < min_s * rate_hz:
            break
        stop = _quiet_until(x[:stop] - x[:stop].mean(axis=0), sigma, n_probe // 4)
    if stop < min_s * rate_hz:
        raise BadInput(source, f"force log leaves its starting level after {stop / rate_hz:.3f} s "
                               f"(need an unloaded start of at least {min_s:g} s to tare from)",
                       where="sample 0")
    seg = x[:stop]
    return Tare(seg.mean(axis=0), seg.std(axis=0), 0, stop)


def _quiet_until(dev: np.ndarray, sigma: np.ndarray, window: int, k: float = 5.0) -> int:
    """First sample of a ``window``-long moving average of ``dev`` that leaves ``k`` of its
    noise widths: the load's onset, found long before single samples leave the noise."""
    if len(dev) < window or window < 2:
        return len(dev)
    ma = np.cumsum(np.vstack([np.zeros((1, dev.shape[1])), dev]), axis=0)
    ma = (ma[window:] - ma[:-window]) / window
    off = (np.abs(ma) > k * sigma / np.sqrt(window)).any(axis=1)
    return int(np.argmax(off)) if off.any() else len(dev)


def apply_calibration(values: np.ndarray, bias: np.ndarray,
                      matrix: np.ndarray | None = None) -> np.ndarray:
    """Wrench (T, 6) = ``matrix @ (values - bias)``; without a matrix the values are a wrench."""
    v = np.asarray(values, float) - np.asarray(bias, float)
    return v if matrix is None else v @ np.asarray(matrix, float).T

"""Force-sensor tare and calibration: raw log to the wrench in the sensor frame.

The bias is the mean of the unloaded start of the recording: the longest stretch from the first
sample over which every channel stays within a few noise widths of its starting level. A log
that starts loaded (or moving) has no such stretch and is refused, since any bias taken from it
would be wrong by the load.

A strain-gauge bias creeps (tens of uN/s: a Nano17 tared once is off by 0.02 N after a few
minutes), and the weight of the tool below the sensor turns with the indenter. So the start
tare is refined by :func:`rest_baseline`: the rest level of the unloaded stretches next to
every press (the hover before contact and after release, where the indenter already has its
press orientation), joined by straight lines, is subtracted from the whole log.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.errors import BadInput
from core.runs import true_runs

TARE_S = 2.0          # the longest unloaded start a tare is taken over (s)


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
    max_s: float = TARE_S,
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


@dataclass
class RestBaseline:
    """The unloaded level of a tared wrench log over time: straight lines between anchors."""

    time_s: np.ndarray    # (K,) anchor times, increasing (the log's clock)
    level: np.ndarray     # (K, C) rest level at each anchor, in the wrench's units

    def at(self, time_s: np.ndarray) -> np.ndarray:
        """The rest level (len(time_s), C), linear between anchors, constant beyond them."""
        t = np.asarray(time_s, float)
        if len(self.time_s) == 0:
            return np.zeros((len(t), self.level.shape[1]))
        return np.stack([np.interp(t, self.time_s, c) for c in self.level.T], axis=1)


def rest_baseline(
    time_s: np.ndarray,
    wrench: np.ndarray,
    contact_n: float,
    coarse_n: float,
    window_s: float = 0.5,
    guard_s: float = 0.1,
    guard_fraction: float = 0.1,
    min_s: float = 0.1,
) -> RestBaseline:
    """The rest level of a tared wrench log (T, C; forces in the first three columns).

    Loaded spans are widened on both sides by ``guard_s`` or ``guard_fraction`` of their own
    length, whichever is longer: the soft start and end of a contact, below the threshold that
    found it, last longer the slower the press. Two passes. Coarse: spans above ``coarse_n``
    (well above any creep, well below a press), widened three times as much; each unloaded
    stretch's median is an anchor at its middle. Fine: with that level removed, spans above
    ``contact_n``; each unloaded stretch (at least ``min_s`` long) gives two anchors, the
    medians of its first and last ``window_s`` (one for a shorter stretch): the rest right
    after a release and right before the next contact. The levels are taken from ``wrench``
    itself, so the result is absolute (subtract it to re-tare). No unloaded stretch at all
    gives an empty baseline (zero everywhere).
    """
    t = np.asarray(time_s, float)
    w = np.asarray(wrench, float)
    rate = 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 1.0     # holes aside
    min_len = max(round(min_s * rate), 1)
    near = _widen(np.linalg.norm(w[:, :3], axis=1) > coarse_n, 3 * guard_s * rate,
                  3 * guard_fraction)
    coarse = _anchors(t, w, near, min_len, None)
    near = _widen(np.linalg.norm((w - coarse.at(t))[:, :3], axis=1) > contact_n,
                  guard_s * rate, guard_fraction)
    return _anchors(t, w, near, min_len, max(round(window_s * rate), 1))


def _widen(loaded: np.ndarray, guard: float, fraction: float) -> np.ndarray:
    """``loaded`` with each True run widened by ``max(guard, fraction * its length)`` samples
    on both sides."""
    out = np.zeros(len(loaded), bool)
    for a, b in true_runs(loaded):
        g = int(round(max(guard, fraction * (b - a))))
        out[max(a - g, 0):b + g] = True
    return out


def _anchors(t: np.ndarray, w: np.ndarray, near: np.ndarray, min_len: int,
             window: int | None) -> RestBaseline:
    """Anchors of the runs outside ``near``: one median per run at its middle (``window``
    None), else the medians of its first and last ``window`` samples (one for a run shorter
    than two windows)."""
    times, levels = [], []
    for a, b in true_runs(~near):
        if b - a < min_len:
            continue
        if window is None or b - a < 2 * window:
            parts = [(a, b)]
        else:
            parts = [(a, a + window), (b - window, b)]
        for lo, hi in parts:
            times.append(float(np.mean(t[lo:hi])))
            levels.append(np.median(w[lo:hi], axis=0))
    if not times:
        return RestBaseline(np.empty(0), np.empty((0, w.shape[1])))
    return RestBaseline(np.array(times), np.array(levels))

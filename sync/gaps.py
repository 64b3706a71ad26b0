"""Filling short marker gaps; longer ones stay missing and flagged.

A gap is a run of missing frames of one marker. A run with seen frames on both sides that lasts
at most ``max_gap_s`` is filled with a cubic Hermite curve that joins the last and the next
seen samples with the velocities of straight-line fits over a few seen frames on each side:
continuous with the data, smooth, and it does not amplify the marker noise the way an
interpolating spline through noisy neighbours does. Runs at the
start or end of the recording, and longer runs, are left NaN: no data are invented for them.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from core.runs import true_runs

FILLED = np.uint8(1)   # quality bit: value interpolated across a short gap
MISSING = np.uint8(2)  # quality bit: no value (gap too long, or at an end)
LOST = np.uint8(8)     # quality bit: the frame was never recorded (a hole, :mod:`sync.holes`)


def fill_gaps(
    time_s: np.ndarray, positions: np.ndarray, max_gap_s: float, support: int = 16,
    never: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Fill short gaps of each point in ``positions`` (T, P, 3) sampled at ``time_s`` (T,).

    A gap's length is its number of missing frames times the frame period (a single missing
    frame at 500 Hz is a 2 ms gap; 20 ms is ten frames); a gap that runs over a frame of
    ``never`` (T,) (a hole's: nothing was recorded there) is not filled, however short.
    Returns the filled copy and per-(frame, point) flags: ``FILLED`` or ``MISSING``.
    """
    t = np.asarray(time_s, float)
    out = np.array(positions, float, copy=True)
    flags = np.zeros(out.shape[:2], np.uint8)
    period = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    for p in range(out.shape[1]):
        missing = ~np.isfinite(out[:, p]).all(axis=1)
        for a, b in true_runs(missing):
            inner = a > 0 and b < len(t) and (never is None or not never[a:b].any())
            if inner and (t[b] - t[a - 1]) - period <= max_gap_s + 1e-9:
                ends = [a - 1, b]
                secant = (out[b, p] - out[a - 1, p]) / (t[b] - t[a - 1])
                slopes = [_slope(t, out[:, p], _seen_before(missing, a, support), a - 1, secant),
                          _slope(t, out[:, p], _seen_after(missing, b, support), b, secant)]
                curve = CubicHermiteSpline(t[ends], out[ends, p], np.stack(slopes), axis=0)
                out[a:b, p] = curve(t[a:b])
                flags[a:b, p] = FILLED
            else:
                out[a:b, p] = np.nan
                flags[a:b, p] = MISSING
    return out, flags


def _slope(t: np.ndarray, x: np.ndarray, idx: np.ndarray, at: int,
           fallback: np.ndarray) -> np.ndarray:
    """Velocity (3,) at frame ``at`` of a least-squares quadratic over frames ``idx`` (a line
    with fewer than 4 frames; ``fallback`` with one)."""
    if len(idx) < 2:
        return fallback
    tt = t[idx] - t[at]
    deg = 2 if len(idx) >= 4 else 1
    coef = np.polynomial.polynomial.polyfit(tt, x[idx], deg)
    return coef[1]


def _seen_before(missing: np.ndarray, a: int, n: int) -> np.ndarray:
    idx: list[int] = []
    i = a - 1
    while i >= 0 and len(idx) < n and not missing[i]:
        idx.append(i)
        i -= 1
    return np.array(idx[::-1], int)


def _seen_after(missing: np.ndarray, b: int, n: int) -> np.ndarray:
    idx: list[int] = []
    i = b
    while i < len(missing) and len(idx) < n and not missing[i]:
        idx.append(i)
        i += 1
    return np.array(idx, int)

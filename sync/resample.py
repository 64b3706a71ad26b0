"""Anti-aliased resampling of the force log onto the mocap frame times.

After clock correction the mocap frames fall at arbitrary (drifting, non-integer) positions of
the logger's grid, so picking every other sample is both aliased and misaligned. Instead the
log is low-pass filtered on its own grid below the output Nyquist frequency with a zero-phase
(symmetric, Kaiser-window) FIR, the same filter a polyphase decimator applies, and then
evaluated at the exact query times with a cubic interpolant.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.interpolate import make_interp_spline
from scipy.signal import firwin, kaiserord


def antialias_taps(
    fs_in: float, fs_out: float, passband: float, atten_db: float = 80.0
) -> np.ndarray:
    """Zero-phase low-pass FIR taps (odd length) for resampling from ``fs_in`` to ``fs_out``.

    Flat to ``passband`` x the output Nyquist frequency, at least ``atten_db`` down at it.
    """
    nyq_out = 0.5 * min(fs_out, fs_in)
    f_pass = passband * nyq_out
    width = (nyq_out - f_pass) / (0.5 * fs_in)
    numtaps, beta = kaiserord(atten_db, width)
    numtaps |= 1
    return firwin(numtaps, 0.5 * (f_pass + nyq_out), window=("kaiser", beta), fs=fs_in)


def lowpass_zero_phase(x: np.ndarray, taps: np.ndarray) -> np.ndarray:
    """Filter along axis 0 with symmetric ``taps`` without delay.

    Each end is padded by odd reflection about the end value of a quadratic fitted to the
    last two thirds of a half filter length of samples there: a ramp passes exactly, motion
    well inside the passband nearly so, and the end samples keep only about half of their
    noise (reflecting about the end sample itself returns that sample, noise and all; a longer
    or straight fit would remove more noise but bend real motion at the ends).
    """
    x = np.asarray(x, float)
    half = len(taps) // 2
    if half == 0:
        return x.copy()
    if len(x) <= half:
        raise ValueError(f"signal of {len(x)} samples is shorter than the filter's half length")
    n = max(4, 2 * half // 3)
    first, last = _fit_end(x[:n]), _fit_end(x[: -n - 1 : -1])
    pad = np.concatenate([2 * first - x[half:0:-1], x, 2 * last - x[-2:-half - 2:-1]])
    flat = pad.reshape(len(pad), -1)
    out = np.stack([np.convolve(flat[:, c], taps, mode="valid") for c in range(flat.shape[1])],
                   axis=1)
    return out.reshape(x.shape)


def _fit_end(x: np.ndarray, degree: int = 2) -> np.ndarray:
    """Value at sample 0 of the least-squares polynomial through ``x`` (n, ...), as (1, ...)."""
    weights = np.linalg.pinv(np.vander(np.arange(len(x), dtype=float), degree + 1,
                                       increasing=True))[0]
    return np.tensordot(weights, x, axes=(0, 0))[None]


def antialiased_interpolant(
    t_src: np.ndarray, x: np.ndarray, fs_out: float, passband: float,
    stretches: list[tuple[int, int]] | None = None,
) -> Callable[[np.ndarray], np.ndarray]:
    """A function of time (s) giving ``x`` (N, ...), sampled at uniform ``t_src`` (s), low-passed
    for an output rate ``fs_out``; NaN outside the source's span. Build once, query often.

    ``stretches`` ([start, stop) sample ranges, each uniform: the runs between the holes of a
    log, :meth:`core.holes.Timing.stretches`) are filtered and interpolated each on its own,
    and a query between two of them is NaN: nothing is interpolated across a hole. A stretch
    shorter than the filter gives NaN too.
    """
    t_src = np.asarray(t_src, float)
    found = [_stretch_interpolant(t_src[a:b], x[a:b], fs_out, passband)
             for a, b in (stretches or [(0, len(t_src))])]
    parts = [part for part in found if part is not None]

    def at(t_query: np.ndarray) -> np.ndarray:
        tq = np.asarray(t_query, float)
        out = np.full((len(tq), *np.shape(x)[1:]), np.nan)
        for part in parts:
            part(tq, out)
        return out

    return at


def _stretch_interpolant(t_src: np.ndarray, x: np.ndarray, fs_out: float, passband: float
                         ) -> Callable[[np.ndarray, np.ndarray], None] | None:
    """One uniform stretch's filtered cubic interpolant, writing the queries inside its span
    into ``out``; None for a stretch shorter than the filter's half length."""
    if len(t_src) < 2:
        return None
    fs_in = (len(t_src) - 1) / (t_src[-1] - t_src[0])
    taps = antialias_taps(fs_in, fs_out, passband)
    if len(t_src) <= len(taps) // 2:
        return None
    spline = make_interp_spline(t_src, lowpass_zero_phase(x, taps), k=3)
    lo, hi = t_src[0], t_src[-1]

    def write(tq: np.ndarray, out: np.ndarray) -> None:
        inside = (tq >= lo) & (tq <= hi)
        if inside.any():
            out[inside] = spline(tq[inside])

    return write


def resample_at(
    t_src: np.ndarray,
    x: np.ndarray,
    t_query: np.ndarray,
    fs_out: float,
    passband: float,
) -> np.ndarray:
    """Values of ``x`` (N, ...) sampled at uniform times ``t_src`` (s), at ``t_query`` (s).

    Anti-aliased for an output rate ``fs_out``. Queries outside the source's span are NaN.
    """
    return antialiased_interpolant(t_src, x, fs_out, passband)(t_query)

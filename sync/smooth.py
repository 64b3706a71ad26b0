"""Zero-phase low-pass smoothing of a tracked point (the indenter tip), gap by gap.

The tip is the cluster's pose applied to an offset about 11 cm away, so the markers' noise
reaches it multiplied by the lever arm (a fraction of a degree of pose noise is half a
millimetre at the tip). A hand moves the indenter at a few hertz, so a zero-phase FIR low-pass
well above that (sync uses 15 Hz) removes most of this noise without delaying or flattening the
motion. Each run of finite samples is filtered on its own; runs shorter than the filter's half
length are left as they are (there is too little to filter), and gaps stay gaps. The ends of a
run are smoothed too (see :func:`sync.resample.lowpass_zero_phase`).
"""

from __future__ import annotations

import numpy as np
from scipy.signal import firwin, kaiserord

from core.runs import true_runs
from sync.resample import lowpass_zero_phase


def smoothing_taps(rate_hz: float, cutoff_hz: float, atten_db: float = 60.0) -> np.ndarray:
    """Odd-length symmetric low-pass taps: flat below ``cutoff_hz``, ``atten_db`` down at 2x."""
    numtaps, beta = kaiserord(atten_db, cutoff_hz / (0.5 * rate_hz))
    return firwin(numtaps | 1, 1.5 * cutoff_hz, window=("kaiser", beta), fs=rate_hz)


def lowpass_track(x: np.ndarray, rate_hz: float, cutoff_hz: float) -> np.ndarray:
    """``x`` (T, ...) low-passed along time, run by run between NaN samples.

    A ``cutoff_hz`` of 0, or one at or above a quarter of ``rate_hz``, returns a copy.
    """
    x = np.asarray(x, float)
    out = x.copy()
    if cutoff_hz <= 0 or cutoff_hz >= 0.25 * rate_hz:
        return out
    taps = smoothing_taps(rate_hz, cutoff_hz)
    finite = np.isfinite(x.reshape(len(x), -1)).all(axis=1)
    for a, b in true_runs(finite):
        if b - a > len(taps) // 2:
            out[a:b] = lowpass_zero_phase(x[a:b], taps)
    return out

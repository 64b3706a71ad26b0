"""The tip against the phantom's rest plane (:mod:`calib.rest_plane`): its depth below it, and
where each press touched it."""

from __future__ import annotations

import numpy as np

from sync.presses import Press


def tip_depth(tip: np.ndarray, point: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Depth (T,) of the tip below the plane through ``point`` along ``normal`` (+: inside)."""
    return (point - tip) @ normal


def contact_points(tip: np.ndarray, presses: list[Press], point: np.ndarray,
                   normal: np.ndarray, frames: int = 10) -> np.ndarray:
    """Where each press touched: the tip over its first loaded frames, on the rest plane.

    The onset, not the peak: a tilted press slides the tip sideways as it sinks in.
    """
    out = np.full((len(presses), 3), np.nan)
    for k, pr in enumerate(presses):
        seg = tip[pr.onset:min(pr.onset + frames, pr.release)]
        seg = seg[np.isfinite(seg).all(axis=1)]
        if len(seg) == 0:
            seg = tip[pr.onset:pr.release]
            seg = seg[np.isfinite(seg).all(axis=1)][:frames]
        if len(seg):
            c = np.median(seg, axis=0)
            out[k] = c - ((c - point) @ normal) * normal
    return out

"""The tip against the phantom's rest surface: the surface itself, the tip's depth below it,
and where each press touched it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calib.phantom_frame import rest_plane
from calib.presses import Press


def rest_surface(phantom: np.ndarray, cluster: np.ndarray, tip: np.ndarray,
                 source: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """The phantom markers' rest plane (a point, the unit normal out of the phantom).

    ``phantom`` (T, 25, 3) and ``cluster`` (T, M, 3) markers, ``tip`` (T, 3): the shaft from
    the tip to the cluster's centre stands above the surface, which orients the normal.
    """
    return rest_plane(phantom, mean_seen(cluster) - tip, source)


def tip_depth(tip: np.ndarray, point: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Depth (T,) of the tip below the plane through ``point`` along ``normal`` (+: inside)."""
    return (point - tip) @ normal


def mean_seen(points: np.ndarray) -> np.ndarray:
    """Mean over axis 1 of (T, M, 3) points, NaN ones left out (NaN where none is seen)."""
    seen = np.isfinite(points).all(axis=2)
    n = seen.sum(axis=1)[:, None]
    total = np.where(seen[..., None], points, 0.0).sum(axis=1)
    return np.where(n > 0, total / np.maximum(n, 1), np.nan)


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

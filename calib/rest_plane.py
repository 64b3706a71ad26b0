"""The phantom's rest plane: the calibration that depth and the phantom frame are measured from.

The phantom markers' rest positions (their medians over a session) fitted by a plane, the
normal turned out of the phantom; a curved phantom is refused."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from core.errors import BadInput

# A flat phantom's markers rest within this of their plane (RMS): marker noise is ~0.1 mm and
# the rest positions are medians; a dome or a limb is millimetres off.
FLAT_RMS_M = 1e-3


def rest_surface(phantom: np.ndarray, cluster: np.ndarray, tip: np.ndarray,
                 source: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """The phantom markers' rest plane (a point, the unit normal out of the phantom).

    ``phantom`` (T, N, 3) and ``cluster`` (T, M, 3) markers, ``tip`` (T, 3): the shaft from
    the tip to the cluster's centre stands above the surface, which orients the normal.
    """
    return rest_plane(phantom, mean_seen(cluster) - tip, source)


def rest_plane(phantom: np.ndarray, up: np.ndarray, source: str | Path
               ) -> tuple[np.ndarray, np.ndarray]:
    """The phantom markers' rest plane: a point and the unit normal out of the phantom.

    Each marker's rest position is its median over the session (it is pressed only a part of
    the time); the plane is their least-squares fit. The normal is turned to agree with ``up``
    (T, 3): the indenter's shaft, from the tip to its marker cluster, which always stands
    above the surface.
    """
    with warnings.catch_warnings():          # a marker never seen has no rest position: NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        rest = np.nanmedian(phantom, axis=0)
    ok = np.isfinite(rest).all(axis=1)
    if ok.sum() < 3:
        raise BadInput(source, "fewer than 3 phantom markers were ever seen: no surface")
    centre = rest[ok].mean(axis=0)
    normal = np.linalg.svd(rest[ok] - centre)[2][2]
    _check_flat(rest[ok], centre, normal, source)
    along = up @ normal
    along = along[np.isfinite(along)]
    if along.size == 0:
        raise BadInput(source, "the indenter is never tracked: no side of the surface is up")
    if np.median(along) < 0:
        normal = -normal
    return centre, normal


def _check_flat(rest: np.ndarray, centre: np.ndarray, normal: np.ndarray,
                source: str | Path) -> None:
    """Refuse a curved phantom: its markers' rest positions far off their best plane (depth and
    the phantom frame are measured from that plane)."""
    off = (rest - centre) @ normal
    rms = float(np.sqrt(np.mean(off ** 2)))
    if rms > FLAT_RMS_M:
        raise BadInput(source, f"the phantom markers at rest lie {rms * 1e3:.2f} mm RMS (up to "
                               f"{np.abs(off).max() * 1e3:.2f} mm) off their best plane, beyond "
                               f"{FLAT_RMS_M * 1e3:g} mm: a curved phantom; the pipeline needs "
                               "a flat one")


def mean_seen(points: np.ndarray) -> np.ndarray:
    """Mean over axis 1 of (T, M, 3) points, NaN ones left out (NaN where none is seen)."""
    seen = np.isfinite(points).all(axis=2)
    n = seen.sum(axis=1)[:, None]
    total = np.where(seen[..., None], points, 0.0).sum(axis=1)
    return np.where(n > 0, total / np.maximum(n, 1), np.nan)

"""The phantom frame: the rest surface of the phantom, found from its markers.

Lab and MSM states share one frame (rest surface at z = 0, +z out of the phantom, footprint
on [0, L] x [0, W]) so that a location means the same place in both.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from core.errors import BadInput


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
    along = up @ normal
    along = along[np.isfinite(along)]
    if along.size == 0:
        raise BadInput(source, "the indenter is never tracked: no side of the surface is up")
    if np.median(along) < 0:
        normal = -normal
    return centre, normal

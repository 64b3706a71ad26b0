"""Pivot calibration: the indenter tip's offset in the cluster's body frame.

While the tip rests in a divot and the indenter is tilted about it, every pose satisfies
``R_k @ tip + t_k = pivot``. Stacking the poses gives a linear least-squares problem in the six
unknowns (tip in the body frame, pivot in the lab). The fit needs rotation about at least two
axes; a recording without it is refused with a clear message instead of a silent guess.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from core.errors import BadInput


@dataclass
class PivotResult:
    """The tip offset and how well the poses agree on it."""

    tip_body: np.ndarray      # (3,) metres, body frame of the cluster
    pivot_lab: np.ndarray     # (3,) metres, lab frame
    rms: float                # RMS distance of R_k @ tip + t_k from the pivot, metres
    n_poses: int
    rotation_spread_deg: float  # spread about the second-best-excited axis (std, degrees)


def rotation_spread_deg(rotations: np.ndarray) -> np.ndarray:
    """Standard deviations (degrees, largest first) of the poses' rotation about three axes.

    The rotation vectors of the poses relative to their mean rotation; the square roots of
    their covariance's eigenvalues. Pivot calibration needs the second one to be large.
    """
    rots = Rotation.from_matrix(rotations)
    rel = (rots.mean().inv() * rots).as_rotvec()
    cov = np.cov(rel.T) if len(rel) > 1 else np.zeros((3, 3))
    return np.degrees(np.sqrt(np.clip(np.linalg.eigvalsh(cov)[::-1], 0, None)))


def pivot_calibrate(
    rotations: np.ndarray,
    translations: np.ndarray,
    source: str | Path | None = None,
    *,
    min_rotation_deg: float,
    min_poses: int = 10,
) -> PivotResult:
    """Least-squares tip offset from poses (K, 3, 3) and (K, 3); NaN poses are skipped.

    Raises :class:`BadInput` naming ``source`` when there are too few poses or too little
    rotation (spread about the second axis below ``min_rotation_deg``): the tip offset along
    the missing axis would be undetermined.
    """
    r = np.asarray(rotations, float)
    t = np.asarray(translations, float)
    good = np.isfinite(r).all(axis=(1, 2)) & np.isfinite(t).all(axis=1)
    r, t = r[good], t[good]
    if len(r) < min_poses:
        raise BadInput(source, f"pivot recording has {len(r)} usable indenter poses, "
                               f"need at least {min_poses}")
    spread = rotation_spread_deg(r)
    if spread[1] < min_rotation_deg:
        raise BadInput(source, f"pivot recording has too little rotation "
                               f"({spread[0]:.2f} and {spread[1]:.2f} deg about its two main "
                               f"axes; need at least {min_rotation_deg:g} deg about two axes)")
    k = len(r)
    a = np.concatenate([r, np.broadcast_to(-np.eye(3), (k, 3, 3))], axis=2).reshape(3 * k, 6)
    x, *_ = np.linalg.lstsq(a, -t.reshape(-1), rcond=None)
    tip, pivot = x[:3], x[3:]
    resid = np.einsum("kij,j->ki", r, tip) + t - pivot
    rms = float(np.sqrt((resid**2).sum(axis=1).mean()))
    return PivotResult(tip, pivot, rms, k, float(spread[1]))

"""A force plate's wrench and its centre of pressure.

A plate reports, in its own frame, the force on it, the moment of that force about its origin
and the point where the force's line of action meets its top surface: the centre of pressure
(COP). With the origin on the top surface (z = 0 there), a force ``F`` through ``(x, y, 0)``
has the moment ``M = (y Fz, -x Fz, x Fy - y Fx)``, so the COP is ``(-My / Fz, Mx / Fz, 0)``.
Below :data:`COP_MIN_N` of vertical force the COP is noise over noise: it is written 0, as
QTM writes it below its COP threshold. Used by the twin (its plate export) and the replay (the
point of application of the force component it serves).
"""

from __future__ import annotations

import numpy as np

COP_MIN_N = 0.05            # |Fz| below which the centre of pressure is 0 (N)


def centre_of_pressure(force: np.ndarray, moment: np.ndarray) -> np.ndarray:
    """The centre of pressure (T, 3) in m of forces (T, 3) in N and their moments (T, 3) in
    N m about an origin on the plate's top surface; 0 where ``|Fz| < COP_MIN_N``."""
    f, m = np.asarray(force, float), np.asarray(moment, float)
    fz = f[:, 2]
    loaded = np.abs(fz) >= COP_MIN_N
    safe = np.where(loaded, fz, 1.0)
    cop = np.column_stack([-m[:, 1] / safe, m[:, 0] / safe, np.zeros(len(f))])
    cop[~loaded] = 0.0
    return cop

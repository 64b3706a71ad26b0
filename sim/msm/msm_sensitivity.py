"""How the MSM's equilibrium moves when one region of its stiffness map grows stiffer.

The map's fit (:mod:`sim.msm.msm_map_fit`) needs, for every measured state, the derivative of
the predicted points with respect to the log factor ``theta_r`` of each region. At an
equilibrium the springs' forces balance the load, ``F(x, theta) = 0``; differentiating,
``K dx = (dF/dtheta_r) dtheta_r`` with ``K`` the tangent stiffness at ``x`` (the exact Hessian
of the energy, :meth:`sim.msm.msm.MSM.stiffness_band`). So one banded solve per region and
state gives the derivative exactly, where finite differences would re-solve every press once
per region.

``dF/dtheta_r`` is the force of the springs whose constant region ``r`` scales, times the
share of that constant that comes from ``r``: a mass's fixed spring wholly (its own factor);
a spring between two masses half per end (its constant is the mean of its ends' factors).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import LinAlgError, solve_banded, solveh_banded

from sim.msm.msm import MSM
from sim.msm.msm_regions import region_of


def mass_regions(model: MSM, shape: tuple[int, int]) -> np.ndarray:
    """The region number (row-major, (N,)) of each mass."""
    idx = region_of(model.rest[:, :2], model.params.footprint, shape)
    return idx[:, 0] * shape[1] + idx[:, 1]


def force_derivatives(model: MSM, x: np.ndarray, regions: np.ndarray, count: int
                      ) -> np.ndarray:
    """``dF/dtheta_r`` (count, N, 3) at state ``x`` (N, 3): the springs' forces (N) per unit
    of log factor of each region; ``regions`` (N,) each mass's region number."""
    out = np.zeros((count, model.N, 3))
    fixed = -np.broadcast_to(model.k_fixed, (model.N, 1)) * (x - model.rest)
    np.add.at(out, (regions, np.arange(model.N)), fixed)
    r, c = model.rows, model.cols
    grid_regions = regions.reshape(r, c)
    grid_ids = np.arange(model.N).reshape(r, c)
    kb0 = model.params.k_between
    factor = _mass_factor(model)
    for (di, dj), d, length in model.springs(x.reshape(r, c, 3)):
        kb = np.broadcast_to(model.k_between[(di, dj)], length.shape)
        stretch = length - model.rest_length[(di, dj)]
        fs = ((kb * stretch / length)[..., None] * d).reshape(-1, 3)   # on end a, minus on b
        a, b = grid_ids[: r - di, : c - dj].ravel(), grid_ids[di:, dj:].ravel()
        for end in (a, b):
            share = (0.5 * kb0 * factor[end] / kb.ravel())[:, None] * fs
            reg = grid_regions.ravel()[end]
            np.add.at(out, (reg, a), share)
            np.add.at(out, (reg, b), -share)
    return out


def state_derivatives(model: MSM, x: np.ndarray, regions: np.ndarray, count: int
                      ) -> np.ndarray:
    """``dx/dtheta_r`` (count, N, 3) at the equilibrium ``x``: ``K^-1 dF/dtheta_r``."""
    rhs = force_derivatives(model, x, regions, count).reshape(count, -1).T    # (3N, count)
    ab = model.stiffness_band(x)
    order = model.band_order
    if order is not None:
        rhs = rhs[order]
    try:
        sol = solveh_banded(ab, rhs, lower=False)
    except LinAlgError:          # compressed springs: the exact tangent is not definite
        bw = model.band_width
        full = np.zeros((2 * bw + 1, ab.shape[1]))
        full[: bw + 1] = ab
        for k in range(1, bw + 1):                       # the lower band, by symmetry
            full[bw + k, : -k] = ab[bw - k, k:]
        sol = solve_banded((bw, bw), full, rhs)
    if order is not None:
        back = np.empty_like(sol)
        back[order] = sol
        sol = back
    return sol.T.reshape(count, model.N, 3)


def _mass_factor(model: MSM) -> np.ndarray:
    """Each mass's map factor (N,): its fixed spring's constant over the uniform one."""
    return np.broadcast_to(np.asarray(model.k_fixed, dtype=float).reshape(-1),
                           (model.N,)) / model.params.k_fixed



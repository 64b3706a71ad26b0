"""A rigid, frictionless sphere pressed into the top face: the contact the Hertz check needs.

Hertz's solution (a sphere of radius R into an elastic half-space, depth d): the force is
``F = 4/3 E / (1 - nu^2) sqrt(R) d^(3/2)`` over a contact of radius ``sqrt(R d)``. The solid's
elasticity answers it with one factorisation: the top face's normal compliance among the
nodes that may touch (one back-substitution per node), then the unilateral contact as a
non-negative least-squares problem: nodal forces ``p >= 0`` with the surface at or below the
sphere everywhere and touching it wherever ``p > 0`` (``min 1/2 p C p - g p``, ``C = L L^T``:
``nnls(L^T, L^-1 g)``). A quarter of the block (its mirror planes x = 0 and y = 0 held) is
pressed at its corner: the whole force is four times the quarter's, a node on one plane
counting half and the corner a quarter.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import nnls

from sim.solid.elasticity import Elasticity, Solver


def hertz_force(modulus: float, poisson: float, radius: float, depth: float) -> float:
    """Hertz's force (N) for a sphere of ``radius`` pressed ``depth`` (m) into a half-space."""
    return 4.0 / 3.0 * modulus / (1.0 - poisson**2) * np.sqrt(radius) * depth**1.5


def sphere_forces(elasticity: Elasticity, solver: Solver, radius: float,
                  depths: np.ndarray, reach: float) -> np.ndarray:
    """The whole force (N) pressing a sphere of ``radius`` each of ``depths`` (m) into the
    quarter block's corner; the top face's nodes within ``reach`` of it may touch."""
    basis, mesh = elasticity.basis, elasticity.mesh
    top = np.flatnonzero(np.isclose(mesh.p[2], mesh.p[2].max()))
    r = np.hypot(mesh.p[0, top], mesh.p[1, top])
    nodes, r = top[r < reach], r[r < reach]
    dofs = basis.nodal_dofs[2, nodes]
    loads = np.zeros((basis.N, len(nodes)))
    loads[dofs, np.arange(len(nodes))] = -1.0               # a unit force into the block
    compliance = -solver.solve(loads)[dofs]                 # (n, n): sinking per unit force
    chol = np.linalg.cholesky(0.5 * (compliance + compliance.T))
    on_x, on_y = np.isclose(mesh.p[0, nodes], 0.0), np.isclose(mesh.p[1, nodes], 0.0)
    mirror = 4.0 * np.where(on_x, 0.5, 1.0) * np.where(on_y, 0.5, 1.0)
    below = radius - np.sqrt(np.clip(radius**2 - r**2, 0.0, None))   # the sphere above flat
    forces = []
    for d in np.atleast_1d(depths):
        gap = d - below                                     # how far each node must sink
        p, _ = nnls(chol.T, np.linalg.solve(chol, gap))
        forces.append(float(mirror @ p))
    return np.array(forces)

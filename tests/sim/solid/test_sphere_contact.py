"""The solid's elasticity against Hertz's contact: a rigid sphere pressed into a thick block.

Known truth: Hertz's force ``4/3 E/(1 - nu^2) sqrt(R) d^(3/2)`` for a half-space. A quarter
block 24 mm on each side (the sphere's contact 3-3.5 mm across, an eighth of it) is meshed
0.5 mm fine over the contact and coarser away; the force at 0.9 and 1.2 mm of depth must be
within 5 % of Hertz's, and it must rise as depth^(3/2) does (not as a linear spring's).
"""

from __future__ import annotations

import numpy as np
import pytest
from skfem import MeshHex

from sim.solid.block_mesh import graded_axis
from sim.solid.elasticity import Elasticity, Material
from sim.solid.sphere_contact import hertz_force, sphere_forces

MODULUS, POISSON, RADIUS = 1.0e4, 0.3, 0.010
DEPTHS = np.array([0.9e-3, 1.2e-3])


@pytest.fixture(scope="module")
def forces() -> np.ndarray:
    axis = graded_axis(0.024, 0.5e-3, 4.5e-3, 1.5)
    mesh = MeshHex.init_tensor(axis, axis, -axis[::-1])
    elasticity = Elasticity(mesh, symmetry=True)
    solver = elasticity.factorise(Material(np.full(elasticity.n_elements, MODULUS), POISSON))
    return sphere_forces(elasticity, solver, RADIUS, DEPTHS, reach=4.5e-3)


def test_force_against_depth_within_5_percent_of_hertz(forces: np.ndarray) -> None:
    hertz = np.array([hertz_force(MODULUS, POISSON, RADIUS, d) for d in DEPTHS])
    assert np.all(np.abs(forces / hertz - 1.0) < 0.05), forces / hertz


def test_force_rises_as_depth_to_the_three_halves(forces: np.ndarray) -> None:
    exponent = np.log(forces[1] / forces[0]) / np.log(DEPTHS[1] / DEPTHS[0])
    assert 1.3 < exponent < 1.7, exponent

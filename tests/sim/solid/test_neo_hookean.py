"""The neo-Hookean solid: its tangent is its forces' derivative, and a small press is linear
elasticity's.

Known truth: calculus (the internal forces' directional derivative by central differences
against the tangent), and the linear solid (scikit-fem's linear forms, a separate code path:
unit responses and :func:`~sim.solid.solid_model.predict`), which a hyperelastic solid must
match as its load goes to zero.
"""

from __future__ import annotations

import numpy as np
import pytest

from sim.solid.block_mesh import BlockGeometry
from sim.solid.elasticity import Material
from sim.solid.neo_hookean import NeoHookean
from sim.solid.solid_model import Attachments, SolidModel, predict

TOP = -0.0015
MODULUS, POISSON, RADIUS = 1e4, 0.3, 0.012


@pytest.fixture(scope="module")
def block() -> SolidModel:
    return SolidModel(BlockGeometry((0.06, 0.06), 0.024, TOP), 0.010, 4)


def _solid(block: SolidModel) -> NeoHookean:
    return NeoHookean(block.elasticity,
                      Material(np.full(block.elasticity.n_elements, MODULUS), POISSON))


def test_the_tangent_is_the_derivative_of_the_internal_forces(block: SolidModel) -> None:
    solid, rng = _solid(block), np.random.default_rng(0)
    u = np.zeros(block.elasticity.basis.N)
    u[block.elasticity.free] = 1e-3 * rng.standard_normal(len(block.elasticity.free))
    v = rng.standard_normal(len(u))
    step = 1e-7
    central = (solid.internal(u + step * v) - solid.internal(u - step * v)) / (2 * step)
    exact = solid.tangent(u) @ v
    assert np.linalg.norm(central - exact) <= 1e-6 * np.linalg.norm(exact)


def test_a_small_press_moves_every_point_as_linear_elasticity_does(block: SolidModel) -> None:
    grid = 0.010 + 0.020 * np.arange(3)
    at = Attachments.riding(np.array([[x, y, 0.0] for y in grid for x in grid]), TOP)
    place, load = np.array([0.03, 0.03, TOP]), np.array([[0.0, 0.0, -1e-3]])   # 1 mN down
    probes = block.probes(at)
    solver = block.factorise(np.ones(block.elasticity.n_elements), POISSON)
    resp = block.respond(solver, place[None], RADIUS, probes)[0]
    lin_pts, lin_tip = predict(resp, load, MODULUS, 0.0, 1.0, at)
    solved = _solid(block).press((block.unit_loads(place, RADIUS)[0] @ load.T).T)
    assert solved.steps[0] <= 4                       # Newton: a few steps at most
    pts, tip = block.observe(solved.fields, place, RADIUS, probes, at)
    rest = at.surface + at.height[:, None] * np.array([0.0, 0.0, 1.0])
    moved = np.linalg.norm(lin_pts[0] - rest, axis=-1).max()
    assert np.linalg.norm(tip - lin_tip) <= 1e-2 * np.linalg.norm(lin_tip - place)
    assert np.linalg.norm(pts - lin_pts, axis=-1).max() <= 1e-2 * moved


def test_a_press_too_deep_for_the_mesh_is_refused_in_one_line(block: SolidModel) -> None:
    place = np.array([0.03, 0.03, TOP])
    loads = (block.unit_loads(place, RADIUS)[0] @ np.array([[0.0, 0.0, -50.0]]).T).T
    with pytest.raises(ValueError, match="inside out|did not converge") as e:
        _solid(block).press(loads)
    assert "\n" not in str(e.value)

"""The solid model of a curved phantom: its block meshed to the mould's shape (columns from the
table to the top surface), pressed as the flat block is; a dome of negligible height answers
as the flat block of the same thickness, and a dome's presses are drawn square to it."""

from __future__ import annotations

import numpy as np
import pytest

from sim.solid.block_mesh import BlockGeometry
from sim.solid.solid_dataset import square_to_surface
from sim.solid.solid_model import Attachments, SolidModel
from sim.twin.twin_shape import dome

THICKNESS = 0.032
SPACING, LAYERS = 0.010, 4


def _curved(height: float) -> SolidModel:
    shape = dome((0.1, 0.1, THICKNESS), height, f"dome:{height * 1e3:g}").shape
    return SolidModel(BlockGeometry((0.1, 0.1), THICKNESS, 0.0, shape), SPACING, LAYERS)


def _centre_tip(model: SolidModel) -> float:
    """The tip's displacement along z under a unit downward load at the footprint's centre."""
    top = float(model.block.top(np.array([[0.05, 0.05]]))[0])
    markers = np.array([[0.03, 0.05, top], [0.07, 0.05, top]])
    at = Attachments.riding(markers, model.block.top(markers[:, :2]))
    solver = model.factorise(np.ones(model.elasticity.n_elements), 0.3)
    resp = model.respond(solver, np.array([[0.05, 0.05, top]]), 0.012, model.probes(at))[0]
    return float(-resp.tip[2, 2])


def test_the_mesh_spans_the_table_to_the_mould() -> None:
    model = _curved(0.03)
    p = model.elasticity.mesh.p
    top = model.block.top(p[:2].T)
    assert np.all(p[2] >= -THICKNESS - 1e-12) and np.all(p[2] <= top + 1e-12)
    on_top = np.isclose(p[2], top, atol=1e-9)
    assert on_top.sum() == len(np.unique(p[0])) * len(np.unique(p[1]))   # one per column
    assert p[2].max() == pytest.approx(0.03, abs=1e-9)                     # the apex


def test_a_low_dome_answers_as_the_flat_block() -> None:
    flat = SolidModel(BlockGeometry((0.1, 0.1), THICKNESS, 0.0), SPACING, LAYERS)
    low = _curved(0.2e-3)
    assert _centre_tip(low) == pytest.approx(_centre_tip(flat), rel=0.02)


def test_a_tall_dome_is_softer_at_its_apex() -> None:
    """The apex column is 62 mm of silicone against the flat block's 32: it gives more."""
    assert _centre_tip(_curved(0.03)) > 1.2 * _centre_tip(
        SolidModel(BlockGeometry((0.1, 0.1), THICKNESS, 0.0), SPACING, LAYERS))


def test_presses_are_drawn_square_to_the_dome() -> None:
    model = _curved(0.03)
    places = np.array([[0.05, 0.05, 0.03], [0.08, 0.05, float(model.block.top(
        np.array([[0.08, 0.05]]))[0])]])
    down = np.tile([0.0, 0.0, -1.0], (2, 1, 1))
    turned = square_to_surface(model, places, down)[:, 0]
    normals = model.block.shape.closest(places)[1]
    np.testing.assert_allclose(turned, -normals, atol=1e-9)
    assert normals[1, 0] > 0.2                        # the flank's normal leans outward

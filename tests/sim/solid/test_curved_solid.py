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


def _sphere(height: float) -> tuple[np.ndarray, float]:
    """The dome's sphere (centre, radius) in its frame: through the footprint's corners."""
    radius = ((np.hypot(0.1, 0.1) / 2) ** 2 + height ** 2) / (2 * height)
    return np.array([0.05, 0.05, height - radius]), radius


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
    """The highest node of each column on the analytic cap (within the mould's facets' sag),
    the lowest on the table."""
    model = _curved(0.03)
    p = model.elasticity.mesh.p.T
    centre, radius = _sphere(0.03)
    columns = np.unique(np.round(p[:, :2], 9), axis=0)
    assert len(columns) == 11 * 11
    for x, y in columns[::7]:
        z = p[np.all(np.isclose(p[:, :2], [x, y], atol=1e-9), axis=1), 2]
        cap = centre[2] + np.sqrt(max(radius ** 2 - (x - 0.05) ** 2 - (y - 0.05) ** 2, 0.0))
        assert z.min() == pytest.approx(-THICKNESS, abs=1e-12)
        assert z.max() == pytest.approx(max(cap, 0.0), abs=0.02e-3)


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
    centre, _ = _sphere(0.03)
    normals = (places - centre) / np.linalg.norm(places - centre, axis=1, keepdims=True)
    np.testing.assert_allclose(turned, -normals, atol=2e-3)    # the sphere's, to its facets
    assert normals[1, 0] > 0.2                        # the flank's normal leans outward


def test_a_mould_whose_top_leaves_its_box_uncovered_is_refused() -> None:
    """A standing cylinder: the corners of its bounding box have no top to mesh up to."""
    import trimesh

    from core.errors import BadInput
    from data_schema.shape import shape_from_mesh

    can = trimesh.creation.cylinder(radius=40.0, height=30.0, sections=48)
    can.apply_translation([40.0, 40.0, 15.0])
    shape = shape_from_mesh(can, "can.stl")
    with pytest.raises(BadInput, match="does not cover its footprint"):
        SolidModel(BlockGeometry((0.08, 0.08), 0.03, 0.0, shape), SPACING, LAYERS)

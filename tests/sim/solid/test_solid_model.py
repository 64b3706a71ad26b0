"""The solid's press: the stiffening law, where it reaches, and what symmetry demands.

Known truth: the cubic ``d + s d^3 = d_lin`` solved in closed form (Cardano), a block pressed at
its centre (its mirror images must move alike), a press of no force (the rest, exactly), and
the patch's load, whose resultant acts at the place and whose total is the patch's integral.
"""

from __future__ import annotations

import numpy as np
import pytest

from data_schema.interior import Interior
from sim.solid.block_mesh import BlockGeometry, axis_nodes, depth_nodes, graded_axis
from sim.solid.label_shares import label_shares
from sim.solid.solid_model import Attachments, SolidModel, point_scale, predict, stiffened

TOP = -0.0015


def test_stiffened_solves_the_cubic_as_cardano_does() -> None:
    d_lin, s = np.array([0.0, 1e-4, 5e-3, 0.02, 0.08]), 2000.0
    p, q = 1.0 / s, -d_lin / s                        # d^3 + p d + q = 0
    root = np.sqrt(q**2 / 4 + p**3 / 27)
    cardano = np.cbrt(-q / 2 + root) + np.cbrt(-q / 2 - root)
    np.testing.assert_allclose(stiffened(d_lin, s), cardano, rtol=1e-9, atol=1e-15)
    np.testing.assert_array_equal(stiffened(d_lin, 0.0), d_lin)


def test_the_stiffening_reaches_the_tip_fully_and_far_points_not_at_all() -> None:
    scale = point_scale(np.array([0.5]), np.zeros(3),
                        np.array([[0.0, 0.0, 0.0], [0.2, 0.0, 0.0]]), reach=0.01)
    np.testing.assert_allclose(scale, [[0.5, 1.0]], atol=1e-12)


def test_mesh_axes() -> None:
    np.testing.assert_allclose(axis_nodes(0.1, 0.005), np.linspace(0, 0.1, 21))
    z = depth_nodes(0.032, 8)
    assert len(z) == 9 and z[0] == 0 and z[-1] == pytest.approx(0.032)
    assert np.allclose(np.diff(z[:5]), 0.002)          # half the layers in the top 8 mm
    g = graded_axis(0.024, 5e-4, 4.5e-3, 1.5)
    assert g[0] == 0 and g[-1] == pytest.approx(0.024) and np.all(np.diff(g) > 0)
    assert np.allclose(np.diff(g)[:9], 5e-4)


@pytest.fixture(scope="module")
def centre_press():
    grid = 0.010 + 0.020 * np.arange(5)
    markers = np.array([[x, y, 0.0] for y in grid for x in grid])
    at = Attachments.riding(markers, TOP)
    model = SolidModel(BlockGeometry((0.1, 0.1), 0.032, TOP), 0.010, 4)
    solver = model.factorise(np.ones(model.elasticity.n_elements), 0.3)
    place = np.array([[0.05, 0.05, TOP]])
    return model.respond(solver, place, 0.015, model.probes(at))[0], at, markers


def test_no_force_leaves_every_point_at_rest(centre_press) -> None:
    resp, at, markers = centre_press
    pts, tip = predict(resp, np.zeros((1, 3)), 1e4, 2000.0, 0.02, at)
    np.testing.assert_allclose(pts[0], markers, atol=1e-15)
    np.testing.assert_allclose(tip[0], resp.place, atol=1e-15)


def test_a_normal_press_at_the_centre_moves_mirror_markers_alike(centre_press) -> None:
    resp, at, markers = centre_press
    pts, tip = predict(resp, np.array([[0.0, 0.0, -3.0]]), 1e4, 2000.0, 0.02, at)
    moved = (pts[0] - markers).reshape(5, 5, 3)          # [row y, column x]
    np.testing.assert_allclose(moved[:, :, 2], moved[:, ::-1, 2], atol=1e-9)   # x mirror
    np.testing.assert_allclose(moved[:, :, 2], moved[::-1, :, 2], atol=1e-9)   # y mirror
    np.testing.assert_allclose(moved[:, :, 0], -moved[:, ::-1, 0], atol=1e-9)
    np.testing.assert_allclose(tip[0, :2], [0.05, 0.05], atol=1e-9)
    assert tip[0, 2] < TOP - 0.005                       # it dents
    assert moved[2, 2, 2] < moved[1, 1, 2] < moved[0, 0, 2]            # deepest at the centre


def test_label_shares_follow_the_volume() -> None:
    """A volume whose lower half (z < -16 mm) is label 1: each element's share is the part of
    it below that plane."""
    model = SolidModel(BlockGeometry((0.04, 0.04), 0.032, 0.0), 0.010, 4)
    labels = np.zeros((40, 40, 32), dtype=np.int64)
    labels[:, :, :16] = 1
    affine = np.eye(4)
    affine[:3, 3] = [0.5, 0.5, -31.5]
    shares = label_shares(model.elasticity, Interior(labels, affine), 2)
    centres_z = model.elasticity.element_centres()[:, 2]
    np.testing.assert_allclose(shares.sum(axis=1), 1.0)
    assert np.all(shares[centres_z < -0.020, 1] == 1.0)
    assert np.all(shares[centres_z > -0.012, 1] == 0.0)


@pytest.mark.parametrize("radius", [0.0065, 0.012])
def test_the_patch_load_acts_at_the_place_wherever_it_falls_between_nodes(radius) -> None:
    """The bump's traction integrated against trilinear shape functions: as those reproduce
    x and y exactly, the shares' first moment is the bump's centroid, the place, wherever it
    falls between the nodes (sharing by the bump's value at the nodes put it up to 0.2 mm off
    at 5 mm, and made the markers' displacements depend on the mesh)."""
    model = SolidModel(BlockGeometry((0.1, 0.1), 0.032, TOP), 0.005, 4)
    xy = model.elasticity.mesh.p[:2]
    for place in ([0.0507, 0.0483], [0.0312, 0.0726], [0.05, 0.05]):
        nodes, share = model.patch(np.array([*place, TOP]), radius)
        assert share.sum() == pytest.approx(1.0) and (share > 0).all()
        np.testing.assert_allclose(xy[:, nodes] @ share, place, atol=2e-6)
        assert np.linalg.norm(xy[:, nodes].T - place, axis=1).max() < radius + 0.005 * 1.5


def test_a_patch_no_quadrature_point_falls_in_is_the_nearest_node() -> None:
    model = SolidModel(BlockGeometry((0.1, 0.1), 0.032, TOP), 0.01, 2)
    nodes, share = model.patch(np.array([0.0498, 0.0501, TOP]), 1e-5)
    np.testing.assert_allclose(model.elasticity.mesh.p[:2, nodes[0]], [0.05, 0.05])
    assert share.tolist() == [1.0]

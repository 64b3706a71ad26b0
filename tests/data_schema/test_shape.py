"""A curved phantom's shape: read from STL, OBJ and PLY in mm, checked, and queried (the closest
surface point, its normal, the signed distance, the top's height) against a sphere's and a
box's analytic answers and against a brute-force search over every face."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from core.errors import BadInput
from data_schema.shape import Shape, read_shape, shape_from_mesh, write_stl

RADIUS_MM = 50.0


def _sphere(path: Path) -> Path:
    trimesh.creation.icosphere(subdivisions=4, radius=RADIUS_MM).export(path)
    return path


@pytest.mark.parametrize("suffix", [".stl", ".obj", ".ply"])
def test_each_format_reads_as_metres(tmp_path: Path, suffix: str) -> None:
    shape = read_shape(_sphere(tmp_path / f"ball{suffix}"))
    r = np.linalg.norm(shape.vertices, axis=1)
    np.testing.assert_allclose(r, RADIUS_MM * 1e-3, rtol=1e-6)


def test_closest_point_normal_and_side_of_a_sphere(tmp_path: Path) -> None:
    shape = read_shape(_sphere(tmp_path / "ball.stl"))
    rng = np.random.default_rng(0)
    p = rng.normal(size=(300, 3)) * 0.03
    at, normal, signed = shape.closest(p)
    r = np.linalg.norm(p, axis=1)
    sag = 0.1e-3                                # the facets lie this far inside the sphere
    np.testing.assert_allclose(signed, r - RADIUS_MM * 1e-3, atol=sag)
    radial = at / np.linalg.norm(at, axis=1, keepdims=True)     # the sphere's normal there
    assert np.degrees(np.arccos(np.clip((normal * radial).sum(1), -1, 1))).max() < 0.5
    np.testing.assert_allclose(np.linalg.norm(at, axis=1), RADIUS_MM * 1e-3, atol=sag)


def test_closest_point_is_the_nearest_of_every_face(tmp_path: Path) -> None:
    """Against a search over every face (trimesh's own point-triangle distance), on a mesh of
    long thin faces where the nearest centroids mislead."""
    mesh = trimesh.creation.cylinder(radius=40.0, height=120.0, sections=24)
    shape = shape_from_mesh(mesh, "cylinder")
    rng = np.random.default_rng(1)
    p = rng.uniform(-0.07, 0.07, size=(60, 3))
    _, _, signed = shape.closest(p)
    tri = np.asarray(mesh.triangles) * 1e-3
    brute = [np.linalg.norm(trimesh.triangles.closest_point(tri, np.repeat(q[None], len(tri), 0))
                            - q, axis=1).min() for q in p]
    np.testing.assert_allclose(np.abs(signed), brute, atol=1e-12)
    behind = np.einsum("pfk,fk->pf", p[:, None] * 1e3 - mesh.triangles_center[None],
                       mesh.face_normals)
    np.testing.assert_array_equal(signed < 0, (behind < 0).all(axis=1))   # convex: inside


def test_height_of_a_box_top() -> None:
    box = trimesh.creation.box(extents=(100.0, 60.0, 30.0))
    shape = shape_from_mesh(box, "box")
    z = shape.height(np.array([[0.0, 0.0], [0.049, -0.029], [0.06, 0.0]]))
    np.testing.assert_allclose(z[:2], 0.015, atol=1e-12)
    assert np.isnan(z[2])                       # outside the footprint


def test_stl_round_trip_keeps_the_surface(tmp_path: Path) -> None:
    shape = shape_from_mesh(trimesh.creation.icosphere(subdivisions=2, radius=20.0), "ball")
    write_stl(tmp_path / "s.stl", shape)
    back = read_shape(tmp_path / "s.stl")
    assert isinstance(back, Shape) and len(back.faces) == len(shape.faces)
    np.testing.assert_allclose(np.sort(back.vertices, axis=0), np.sort(shape.vertices, axis=0),
                               atol=1e-9)


def _open_box(path: Path) -> Path:
    box = trimesh.creation.box(extents=(50.0, 50.0, 20.0))
    box.update_faces(np.arange(len(box.faces)) > 1)       # one side's two triangles gone
    box.export(path)
    return path


def _metres(path: Path) -> Path:
    trimesh.creation.icosphere(radius=0.05).export(path)
    return path


def _degenerate(path: Path) -> Path:
    """A tetrahedron closed only by a zero-area face: one side's edge AB is split at its
    midpoint M, and the sliver A-B-M joins the split side to the unsplit one."""
    a, b, c, d, m = (0, 0, 0), (40, 0, 0), (0, 40, 0), (0, 0, 40), (20, 0, 0)
    faces = [(1, 3, 2), (1, 4, 3), (2, 3, 4), (1, 5, 4), (5, 2, 4), (1, 2, 5)]
    path.write_text("\n".join([*(f"v {x} {y} {z}" for x, y, z in (a, b, c, d, m)),
                               *(f"f {i} {j} {k}" for i, j, k in faces)]))
    return path


def _points(path: Path) -> Path:
    trimesh.PointCloud(np.random.default_rng(0).normal(size=(20, 3)) * 10).export(path)
    return path


@pytest.mark.parametrize("make, name, what", [
    (lambda p: (p.write_text("solid x\nnot a facet\n"), p)[1], "junk.stl", "not a surface mesh"),
    (_points, "cloud.ply", "not a surface mesh"),
    (_open_box, "open.stl", "not watertight"),
    (_metres, "metres.stl", "thousand times off"),
    (_degenerate, "flat.obj", "degenerate face"),
    (lambda p: (p.write_text("x"), p)[1], "shape.step", "STL, OBJ or PLY"),
    (lambda p: p, "absent.stl", "does not exist"),
])
def test_bad_shapes_are_refused_in_one_line(tmp_path: Path, make, name: str, what: str) -> None:
    path = make(tmp_path / name)
    with pytest.raises(BadInput) as e:
        read_shape(path)
    line = str(e.value)
    assert what in line and "\n" not in line and name in line


def test_exact_near_the_surface_and_bounded_beyond(tmp_path: Path) -> None:
    """With ``exact_within``, points that near are answered exactly; farther ones by the first
    guess, never farther off than the largest face's reach."""
    shape = read_shape(_sphere(tmp_path / "ball.stl"))
    rng = np.random.default_rng(2)
    p = rng.normal(size=(400, 3)) * 0.04
    exact = shape.closest(p)[2]
    banded = shape.closest(p, exact_within=5e-3)[2]
    near = np.abs(exact) <= 5e-3
    assert near.any() and (~near).any()
    np.testing.assert_array_equal(banded[near], exact[near])
    reach = shape._fine[2].max()
    assert np.all(np.abs(banded) - np.abs(exact) <= reach + 1e-12)


def test_flipped_faces_are_turned_to_agree() -> None:
    """A box two of whose faces are wound the other way (as scans export them): the signed
    distance of a point just inside that side is still negative."""
    box = trimesh.creation.box(extents=(50.0, 50.0, 20.0))
    faces = np.asarray(box.faces).copy()
    faces[:2] = faces[:2, ::-1]
    shape = shape_from_mesh(trimesh.Trimesh(box.vertices, faces, process=True), "flipped")
    side = box.triangles_center[0] * 1e-3
    inward = -box.face_normals[0] * 1e-4
    _, normal, signed = shape.closest((side + inward)[None])
    assert signed[0] == pytest.approx(-1e-4, abs=1e-9)
    np.testing.assert_allclose(normal[0], box.face_normals[0], atol=1e-9)

"""A curved phantom's shape: the surface of its mould or scan, and where a point lies on it.

session.toml's ``[phantom] shape = "FILE"`` names an STL, OBJ or PLY surface (read with
trimesh) in millimetres, in the phantom's own frame with +z out of the phantom at the top. That
frame becomes the phantom frame of every file after sync: the markers are registered to the
surface (:mod:`calib.shape_registration`) and depth is measured along its normal where the tip
touched. A session without ``shape`` is the flat phantom, measured from its rest plane.

Refused in one line: a file trimesh cannot read as a surface (a point cloud, text, nothing);
a surface with degenerate faces that removing them leaves open; one that is not watertight
(the solid inside it is what presses deform); faces that cannot be wound one way round (a
scan's flipped faces are turned to agree); a size a thousand times off (metres or
micrometres written as mm).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from core.bounds import Bound
from core.errors import BadInput

SIZE_MM = Bound(5.0, 3000.0, unit="mm", why="metres or micrometres written as mm are a "
                                             "thousand times off")
SUFFIXES = (".stl", ".obj", ".ply")
CANDIDATES = 16          # nearest faces (by centroid) of a point's first guess at its closest
FINE = 1 / 20            # queries cut the surface into triangles this short (of its extent)
CREASE_DEG = 30.0        # faces meeting at a sharper angle are an edge of the mould


@dataclass(frozen=True)
class Shape:
    """A closed triangle surface in the phantom frame (metres), faces wound outward."""

    vertices: np.ndarray     # (V, 3) m
    faces: np.ndarray        # (F, 3) vertex indices

    def as_json(self) -> dict:
        """Plain lists (mm to the micrometre) for the session's and the synced file's JSON."""
        return {"vertices_mm": np.round(self.vertices * 1e3, 3).tolist(),
                "faces": self.faces.tolist()}

    @classmethod
    def from_json(cls, d: dict) -> Shape:
        """Back from :meth:`as_json`."""
        return cls(np.asarray(d["vertices_mm"], dtype=np.float64) * 1e-3,
                   np.asarray(d["faces"], dtype=np.int64))

    @cached_property
    def _mesh(self) -> trimesh.Trimesh:
        return trimesh.Trimesh(self.vertices, self.faces, process=False)

    @cached_property
    def _fine(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The surface cut into triangles no longer than :data:`FINE` of its extent (queries
        stay local): (F', 3, 3) corners, (F', 3) their face's outward normal, (F',) each
        centroid's reach (to its farthest corner), (F',) the face of the shape it lies in."""
        edge = float(self._mesh.extents.max()) * FINE
        verts, faces, index = trimesh.remesh.subdivide_to_size(
            self.vertices, self.faces, max_edge=edge, return_index=True)
        tri = verts[faces]
        reach = np.linalg.norm(tri - tri.mean(axis=1, keepdims=True), axis=2).max(axis=1)
        return tri, self._mesh.face_normals[index], reach, index

    @cached_property
    def _corner_normals(self) -> np.ndarray:
        """(F, 3, 3) each face's normal at its corners: the area-weighted mean of the faces
        around the corner's vertex that turn less than :data:`CREASE_DEG` from it, so normals
        blend across a smooth surface and stay apart across a mould's edges."""
        mesh = self._mesh
        around = mesh.vertex_faces[self.faces]                       # (F, 3, D), -1 padded
        normals = mesh.face_normals[around]                         # (F, 3, D, 3)
        smooth = np.einsum("fcdk,fk->fcd", normals, mesh.face_normals) > np.cos(
            np.radians(CREASE_DEG))
        weight = np.where((around >= 0) & smooth, mesh.area_faces[around], 0.0)
        out = np.einsum("fcd,fcdk->fck", weight, normals)
        return out / np.linalg.norm(out, axis=2, keepdims=True)

    @cached_property
    def _tree(self) -> cKDTree:
        return cKDTree(self._fine[0].mean(axis=1))

    def closest(self, points: np.ndarray, exact_within: float = np.inf
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For (P, 3) points: the closest surface points (P, 3), the surface's outward unit
        normal there (P, 3; the face's corner normals blended, so it turns smoothly across a
        curved surface's facets), and the signed distances (P,): positive outside, negative
        inside.

        Exact for points whose first guess lies within ``exact_within`` (m) of the surface: the
        first guess is the nearest of the :data:`CANDIDATES` faces nearest by centroid, then
        every face whose centroid lies within that distance plus the largest face's reach is
        searched. Farther out the first guess stands: never more than that reach too far (on
        34,000 tip positions of the dome twin it equalled the exact distance, in a tenth of the
        time: docs/results.md, "Curved phantoms")."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        tri, normals, reach, index = self._fine
        k = min(CANDIDATES, len(tri))
        first = self._tree.query(p, k=k)[1].reshape(len(p), k)
        at, face, dist = _nearest(tri, p, np.repeat(np.arange(len(p)), k), first.ravel())
        near = np.flatnonzero(dist <= exact_within)
        if near.size:
            balls = self._tree.query_ball_point(p[near], dist[near] + reach.max() + 1e-12)
            owner = np.repeat(near, [len(b) for b in balls])
            found = np.concatenate([np.asarray(b, dtype=np.int64) for b in balls])
            at[near], face[near], dist[near] = _nearest(tri, p, owner, found)
        side = np.where(np.einsum("ij,ij->i", p - at, normals[face]) < 0, -1.0, 1.0)
        return at, self._blended_normal(index[face], at), side * dist

    def height(self, xy: np.ndarray) -> np.ndarray:
        """(P,) the top surface's z above each (P, 2) point (m): the highest face crossed by
        a vertical line; NaN where none is (outside the footprint)."""
        q = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        tri = self._fine[0]
        up, tree, reach = self._upward
        balls = tree.query_ball_point(q, reach + 1e-12)
        owner = np.repeat(np.arange(len(q)), [len(b) for b in balls])
        face = up[np.concatenate([np.asarray(b, dtype=np.int64) for b in balls])]
        bary = trimesh.triangles.points_to_barycentric(
            tri[face] * [1.0, 1.0, 0.0], np.c_[q[owner], np.zeros(len(owner))])
        inside = (bary >= -1e-9).all(axis=1)
        z = np.einsum("ij,ij->i", bary, tri[face][:, :, 2])
        out = np.full(len(q), -np.inf)
        np.maximum.at(out, owner[inside], z[inside])
        return np.where(np.isfinite(out), out, np.nan)

    @cached_property
    def _upward(self) -> tuple[np.ndarray, cKDTree, float]:
        """The fine faces that look up, a tree of their centroids in x, y and their largest
        reach there: what :meth:`height` searches."""
        tri, normals, _, _ = self._fine
        up = np.flatnonzero(normals[:, 2] > 1e-9)
        flat = tri[up][:, :, :2]
        reach = np.linalg.norm(flat - flat.mean(axis=1, keepdims=True), axis=2).max(axis=1)
        return up, cKDTree(flat.mean(axis=1)), float(reach.max())

    def _blended_normal(self, face: np.ndarray, at: np.ndarray) -> np.ndarray:
        bary = trimesh.triangles.points_to_barycentric(self._mesh.triangles[face], at)
        n = np.einsum("ij,ijk->ik", bary, self._corner_normals[face])
        return n / np.linalg.norm(n, axis=1, keepdims=True)


def _nearest(tri: np.ndarray, p: np.ndarray, owner: np.ndarray, face: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Among the (owner point, face) pairs, each owner's closest face: its point on it (U, 3),
    the face (U,) and the distance (U,), owners in ascending order (each owner once)."""
    at = trimesh.triangles.closest_point(tri[face], p[owner])
    dist = np.linalg.norm(at - p[owner], axis=1)
    order = np.lexsort((dist, owner))
    best = order[np.r_[0, np.flatnonzero(np.diff(owner[order])) + 1]]
    return at[best], face[best], dist[best]


def read_shape(path: Path) -> Shape:
    """The surface in ``path`` (mm) as a :class:`Shape` in metres, or one line refusing it."""
    if path.suffix.lower() not in SUFFIXES:
        suffix = path.suffix or "no suffix"
        raise BadInput(path, f"a shape is an STL, OBJ or PLY surface; {suffix} is none of them")
    if not path.is_file():
        raise BadInput(path, "the shape file does not exist")
    try:
        mesh = trimesh.load(path, force="mesh", process=True)
    except Exception as exc:   # noqa: BLE001 - trimesh raises many kinds for a bad file
        raise BadInput(path, f"not a surface mesh trimesh can read ({exc})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise BadInput(path, "not a surface mesh: no triangles (a point cloud or an empty file)")
    return shape_from_mesh(mesh, path)


def shape_from_mesh(mesh: trimesh.Trimesh, source: Path | str) -> Shape:
    """A mesh in mm checked (size, degenerate faces, watertight) and turned into a Shape."""
    extent = float(mesh.extents.max())
    if not SIZE_MM.holds(extent):
        SIZE_MM.check(f"{source}: its largest extent", extent, f"{extent:g}")
    good = mesh.nondegenerate_faces(height=extent * 1e-7)
    if not good.all():
        mesh = mesh.copy()
        mesh.update_faces(good)
        mesh.remove_unreferenced_vertices()
        mesh.merge_vertices()
        if not mesh.is_watertight:
            raise BadInput(source, f"{int((~good).sum())} degenerate face(s): removing them "
                                   "leaves holes in the surface, beyond repair")
    if not mesh.is_watertight:
        raise BadInput(source, "the surface is not watertight: the solid inside it is not "
                               "closed (holes or open edges)")
    if not mesh.is_winding_consistent:          # a scan's flipped faces: turned to agree
        mesh = mesh.copy()
        trimesh.repair.fix_winding(mesh)
        if not mesh.is_winding_consistent:
            raise BadInput(source, "its faces cannot be wound one way round: no inside and "
                                   "outside")
    if mesh.volume < 0:
        mesh.invert()
    return Shape(np.asarray(mesh.vertices, dtype=np.float64) * 1e-3,
                 np.asarray(mesh.faces, dtype=np.int64))


def write_stl(path: str | Path, shape: Shape) -> None:
    """``shape`` as a binary STL in mm, whatever the path's name (a temporary one)."""
    mesh = trimesh.Trimesh(shape.vertices * 1e3, shape.faces, process=False)
    Path(path).write_bytes(trimesh.exchange.stl.export_stl(mesh))


def heightfield_solid(xs: np.ndarray, ys: np.ndarray, top, base: float) -> trimesh.Trimesh:
    """A closed surface in mm: the top ``top((P, 2) m) -> (P,) m`` sampled on the grid
    ``xs`` x ``ys`` (m), a flat bottom at ``base`` (m), and the side walls between them."""
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    xy = np.c_[gx.ravel(), gy.ravel()]
    n = len(xy)
    verts = np.r_[np.c_[xy, top(xy)], np.c_[xy, np.full(n, base)]] * 1e3
    idx = np.arange(n).reshape(len(xs), len(ys))
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    quads = np.stack([a, b, c, d], -1).reshape(-1, 4)
    ring = np.r_[idx[:, 0], idx[-1, 1:], idx[-2::-1, -1], idx[0, -2:0:-1]]
    walls = np.stack([ring, np.roll(ring, -1), np.roll(ring, -1) + n, ring + n], -1)
    faces = np.r_[quad_triangles(quads), quad_triangles(quads[:, ::-1] + n),
                  quad_triangles(walls[:, ::-1])]
    mesh = trimesh.Trimesh(verts, faces, process=True)
    trimesh.repair.fix_normals(mesh)
    return mesh


def quad_triangles(quads: np.ndarray) -> np.ndarray:
    """Each quad (a, b, c, d) as two triangles (a, b, c) and (a, c, d)."""
    return np.r_[quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]

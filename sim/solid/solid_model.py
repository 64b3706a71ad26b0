"""The solid phantom pressed at a place: the response of its markers and of the tip.

A press is the tip's load ``F`` (N, a vector) on the silicone around the place it touches: a
traction over the top face within ``contact_radius`` ``a`` of it, shaped as the bump
``(1 - r^2 / a^2)^2``, which falls to zero with its slope at the patch's edge, so that the load
changes smoothly as the radius grows (a Hertz pressure, ``sqrt(1 - r^2 / a^2)``, enters with
an infinite slope: the fit's radius then caught on the mesh's node distances). Each top node
carries the traction integrated against its shape function over the top's facets (scikit-fem's
linear form): the load the elements see, whatever the mesh. Sharing it out by the bump's value
at the nodes instead made the markers' displacements depend on the mesh (4 % from 5 to 3.33
mm; 0.8-1.1 % so integrated, pressed between markers), and the tip's (the patch's
load-weighted displacement, the work conjugate of these shares) 14 %. Linear elasticity makes
every press at a place a sum of three unit responses (one per axis), each one
back-substitution on the factorised stiffness, computed at unit modulus and scaled by ``1 / E``.

Silicone stiffens as it is pressed deep, most where it is strained most: under the tip. The
solid keeps the linear field's shape and maps its size there: a linear tip displacement
``d_lin`` becomes ``d`` with ``d + stiffening * d^3 = d_lin`` (``stiffening`` in 1/m^2; 0 is
linear elasticity). Away from the tip the strains are small and the field stays linear in the
force (the load it carries is the same, however the tip's neighbourhood stiffens): a point at
rest distance ``r`` from the place takes the factor ``1 + w (d / d_lin - 1)`` with
``w = exp(-(r / reach)^2)``, ``reach`` the stiffening's reach (m).

A marker sits on the surface, its centre a little above it (the lab's rest positions say how
far): it moves with the surface point under it and turns with the surface's normal, which the
displacement's gradient across the top gives (central differences of the field).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.interpolate import RegularGridInterpolator
from scipy.spatial import Delaunay
from skfem import ElementHex1, FacetBasis, LinearForm, asm

from core.bounds import Bound
from sim.solid.block_mesh import BlockGeometry, block_mesh
from sim.solid.elasticity import Elasticity, Material, Solver

CONTACT_RADIUS = Bound(0.5e-3, 20e-3, unit="m")
REACH = Bound(1e-3, 0.5, unit="m")     # the stiffening's reach: from the tip alone to the block
SLOPE_STEP = 1e-3          # m: the central differences that give the surface's tangents
UNDER_TOP = 0.1e-3         # m: a curved top's probes sit this far under its mesh's top face
PATCH_ORDER = 8            # the top facets' quadrature (5 x 5 Gauss points, 1 mm apart at 5 mm)


@dataclass(frozen=True)
class Attachments:
    """Where points ride on the top face: the surface point under each, its offset above."""

    surface: np.ndarray     # (P, 3) the surface point under each (on the top face)
    height: np.ndarray      # (P,) m above it (a marker's centre): along the normal on a flat
    #                         top, where the two agree; straight up on a curved one

    @classmethod
    def riding(cls, rest: np.ndarray, top_z: float | np.ndarray) -> Attachments:
        """Markers resting at ``rest`` (P, 3) on a top face at height ``top_z`` (one, or
        (P,) each's: a curved top's under it): each on the surface point below it, as high
        above it as it rests."""
        surface = np.array(rest, dtype=np.float64)
        surface[:, 2] = top_z
        return cls(surface=surface, height=np.asarray(rest, dtype=np.float64)[:, 2] - top_z)


@dataclass(frozen=True)
class PlaceResponse:
    """The displacements at one place per unit load along x, y and z (at unit modulus)."""

    place: np.ndarray       # (3,) the contact point at rest (the tip's rest)
    points: np.ndarray      # (3, P, 3) at each attached point's surface point
    slope_x: np.ndarray     # (3, P, 3) d/dx of the displacement there
    slope_y: np.ndarray     # (3, P, 3) d/dy
    tip: np.ndarray         # (3, 3) the patch's load-weighted displacement


@dataclass(frozen=True)
class Probes:
    """Interpolation matrices at points and beside them along x and y (lo, hi each)."""

    matrices: tuple[sp.csr_matrix, ...]   # at, x lo, x hi, y lo, y hi: (3P, N) each
    steps: tuple[np.ndarray, np.ndarray]  # (P,) the x and y differences' widths
    n_points: int

    def field(self, matrix: sp.csr_matrix, u: np.ndarray) -> np.ndarray:
        """(K, P, 3) the K fields ``u`` (N, K) through ``matrix`` (component-major)."""
        return (matrix @ u).reshape(3, self.n_points, -1).transpose(2, 1, 0)


class SolidModel:
    """A block on the table, its mesh and elasticity: factorised per material."""

    def __init__(self, block: BlockGeometry, spacing: float, layers: int) -> None:
        self.block = block
        self.spacing = spacing
        self.elasticity = Elasticity(block_mesh(block, spacing, layers))
        mesh = self.elasticity.mesh
        top = np.flatnonzero(np.isclose(mesh.p[2], block.top(mesh.p[:2].T), rtol=0,
                                        atol=1e-9))
        self._top_nodes = top
        self._top_xy = mesh.p[:2, top].T
        on_top = np.flatnonzero(np.isin(mesh.facets, top).all(axis=0))
        self._top_facets = FacetBasis(mesh, ElementHex1(), facets=on_top, intorder=PATCH_ORDER)

    def factorise(self, modulus: np.ndarray, poisson: float) -> Solver:
        """The stiffness with ``modulus`` per element (Pa, relative: 1 is the block's)."""
        return self.elasticity.factorise(Material(np.asarray(modulus, float), poisson))

    def patch(self, place: np.ndarray, contact_radius: float) -> tuple[np.ndarray, np.ndarray]:
        """Top-face nodes under the tip at ``place`` and their load shares (sum 1): the bump's
        traction integrated against each node's shape function (a patch no quadrature point
        falls in: the nearest node)."""
        centre = np.asarray(place, dtype=np.float64)[:2]

        @LinearForm
        def traction(v, w):            # noqa: ANN001, ANN202 (scikit-fem's form signature)
            r2 = ((w.x[0] - centre[0]) ** 2 + (w.x[1] - centre[1]) ** 2) / contact_radius ** 2
            return np.where(r2 < 1.0, (1.0 - r2) ** 2, 0.0) * v

        load = asm(traction, self._top_facets)
        nodes = np.flatnonzero(load > 0.0)
        if nodes.size == 0:
            r = np.linalg.norm(self._top_xy - centre, axis=1)
            return self._top_nodes[[int(np.argmin(r))]], np.ones(1)
        return nodes, load[nodes] / load[nodes].sum()

    def probes(self, at: Attachments) -> Probes:
        """The interpolation at the attached points' surface points, and beside them (the
        central differences of the slopes), built once for many presses."""
        x = np.clip(at.surface, self.block.lower, self.block.upper)
        if self.block.shape is not None:           # on the mesh's own top: its facets' chords
            x[:, 2] = self._mesh_top(x[:, :2])
        matrices, steps = [self._probe_matrix(x)], []
        for axis in range(2):
            lo, hi = x.copy(), x.copy()
            lo[:, axis] = np.maximum(x[:, axis] - SLOPE_STEP, self.block.lower[axis])
            hi[:, axis] = np.minimum(x[:, axis] + SLOPE_STEP, self.block.upper[axis])
            if self.block.shape is not None:       # beside it on the curved top, not above
                lo[:, 2], hi[:, 2] = self._mesh_top(lo[:, :2]), self._mesh_top(hi[:, :2])
            matrices += [self._probe_matrix(lo), self._probe_matrix(hi)]
            steps.append(hi[:, axis] - lo[:, axis])
        return Probes(matrices=tuple(matrices), steps=tuple(steps), n_points=len(x))

    def respond(self, solver: Solver, places: np.ndarray, contact_radius: float,
                probes: Probes) -> list[PlaceResponse]:
        """Unit responses at each of ``places`` (P, 3): three back-substitutions a place, all
        in one call."""
        basis = self.elasticity.basis
        patches = [self.unit_loads(p, contact_radius) for p in places]
        u = solver.solve(np.concatenate([loads for loads, _, _ in patches], axis=1))
        out = []
        for i, (place, (_, nodes, share)) in enumerate(zip(places, patches, strict=True)):
            ui = u[:, 3 * i:3 * i + 3]                            # (N, 3): unit x, y, z
            tip = np.stack([ui[basis.nodal_dofs[:, nodes], k] @ share for k in range(3)])
            at, xlo, xhi, ylo, yhi = (probes.field(m, ui) for m in probes.matrices)
            out.append(PlaceResponse(place=np.asarray(place, float), points=at,
                                     slope_x=(xhi - xlo) / probes.steps[0][None, :, None],
                                     slope_y=(yhi - ylo) / probes.steps[1][None, :, None],
                                     tip=tip))
        return out

    def observe(self, fields: np.ndarray, place: np.ndarray, contact_radius: float,
                probes: Probes, at: Attachments) -> tuple[np.ndarray, np.ndarray]:
        """The attached points (T, P, 3) and the tip (T, 3) of the fields (T, N) of a press at
        ``place`` (the tip: its patch's load-weighted displacement), however they were
        solved (the neo-Hookean solid's)."""
        nodes, share = self.patch(place, contact_radius)
        dofs = self.elasticity.basis.nodal_dofs[:, nodes]                 # (3, nodes)
        tip = np.asarray(place, float)[None] + fields[:, dofs] @ share    # (T, 3)
        disp, xlo, xhi, ylo, yhi = (probes.field(m, fields.T) for m in probes.matrices)
        return ride(at, disp, (xhi - xlo) / probes.steps[0][None, :, None],
                    (yhi - ylo) / probes.steps[1][None, :, None]), tip

    def surface(self, solver: Solver, place: np.ndarray, contact_radius: float
                ) -> np.ndarray:
        """(3 loads, top nodes, 3) the top face's unit responses at ``place`` (for a view)."""
        u = solver.solve(self.unit_loads(place, contact_radius)[0])
        basis = self.elasticity.basis
        return np.stack([u[basis.nodal_dofs[:, self._top_nodes], k].T for k in range(3)])

    def top_face(self) -> tuple[np.ndarray, np.ndarray]:
        """The top face at rest: its nodes (n, 3) and triangles (m, 3)."""
        rest = self.elasticity.mesh.p[:, self._top_nodes].T
        return rest, Delaunay(self._top_xy).simplices

    def unit_loads(self, place: np.ndarray, contact_radius: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(N, 3) the patch's unit loads along x, y and z; its nodes and their shares."""
        basis = self.elasticity.basis
        nodes, share = self.patch(place, contact_radius)
        loads = np.zeros((basis.N, 3))
        for axis in range(3):
            loads[basis.nodal_dofs[axis, nodes], axis] = share
        return loads, nodes, share

    def _mesh_top(self, xy: np.ndarray) -> np.ndarray:
        """(P,) a height just under the mesh's top face over (P, 2) points: bilinear between its
        top nodes, less :data:`UNDER_TOP` (the element finder splits each hexahedron into
        tetrahedra, whose top triangles sag below the bilinear face; a curved shape's surface
        bulges above both by the chords' sag)."""
        xs, ys = np.unique(self._top_xy[:, 0]), np.unique(self._top_xy[:, 1])
        z = np.empty((len(xs), len(ys)))
        z[np.searchsorted(xs, self._top_xy[:, 0]), np.searchsorted(ys, self._top_xy[:, 1])] = \
            self.elasticity.mesh.p[2, self._top_nodes]
        below = RegularGridInterpolator((xs, ys), z)(np.clip(xy, [xs[0], ys[0]], [xs[-1], ys[-1]]))
        return below - UNDER_TOP

    def _probe_matrix(self, x: np.ndarray) -> sp.csr_matrix:
        return self.elasticity.basis.probes(x.T).tocsr()


def stiffened(d_lin: np.ndarray, stiffening: float) -> np.ndarray:
    """``d`` with ``d + stiffening * d**3 = d_lin`` (d_lin >= 0): Newton from ``d_lin``, an
    upper bound on the convex, rising cubic, so it falls monotonically onto the root."""
    d_lin = np.asarray(d_lin, dtype=np.float64)
    if stiffening <= 0.0:
        return d_lin.copy()
    d = d_lin.copy()
    for _ in range(60):
        step = (d + stiffening * d**3 - d_lin) / (1.0 + 3.0 * stiffening * d**2)
        d -= step
        if np.all(np.abs(step) <= 1e-12):
            break
    return d


def tip_scale(tip_lin: np.ndarray, stiffening: float) -> np.ndarray:
    """(T,) ``d / d_lin`` for the linear tip displacements (T, 3)."""
    d_lin = np.linalg.norm(tip_lin, axis=1)
    return np.divide(stiffened(d_lin, stiffening), d_lin, out=np.ones_like(d_lin),
                     where=d_lin > 0)


def point_scale(tip: np.ndarray, place: np.ndarray, points: np.ndarray, reach: float
                ) -> np.ndarray:
    """(T, P) the factor on each point's linear displacement, from the tip's (T,) and each
    point's rest distance from the place."""
    r = np.linalg.norm(points[:, :2] - place[None, :2], axis=1)
    w = np.exp(-((r / reach) ** 2))
    return 1.0 + w[None, :] * (tip[:, None] - 1.0)


def predict(resp: PlaceResponse, loads: np.ndarray, modulus: float, stiffening: float,
            reach: float, at: Attachments) -> tuple[np.ndarray, np.ndarray]:
    """The attached points (T, P, 3) and the tip (T, 3) under ``loads`` (T, 3) N."""
    tip = loads @ resp.tip / modulus                                   # (T, 3) linear
    s_tip = tip_scale(tip, stiffening)
    scale = point_scale(s_tip, resp.place, at.surface, reach)[..., None]   # (T, P, 1)
    disp = np.einsum("tk,kpc->tpc", loads, resp.points) / modulus * scale
    gx = np.einsum("tk,kpc->tpc", loads, resp.slope_x) / modulus * scale
    gy = np.einsum("tk,kpc->tpc", loads, resp.slope_y) / modulus * scale
    return ride(at, disp, gx, gy), resp.place[None] + tip * s_tip[:, None]


def ride(at: Attachments, disp: np.ndarray, gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
    """(T, P, 3) the attached points on a surface moved by ``disp`` (T, P, 3) with slopes
    ``gx``, ``gy`` (T, P, 3: d disp / dx, dy there): each on its surface point, turned with
    the surface's normal."""
    normal = np.cross(gx + np.array([1.0, 0.0, 0.0]), gy + np.array([0.0, 1.0, 0.0]))
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    return at.surface[None] + disp + at.height[None, :, None] * normal

"""The phantom twin's silicone block: a volumetric spring lattice with a strain-stiffening material.

The block (100 x 100 x 32 mm by default; any footprint) is a lattice of nodes (21 x 21 x 5 by
default: 5 mm across, 8 mm through the thickness; finer across for a dense marker grid, and
the outermost cells closed by the block's edges: :mod:`sim.twin.marker_layout`) joined by
springs along the edges, the face diagonals and the body diagonals of every cell (13
directions per node); its bottom layer is fixed to the table. It is
volumetric on purpose: the network is pre-trained on a surface mass-spring model, and the twin
must leave it a real gap to cross.

Kinematics are linearised (a spring's strain is the relative displacement of its ends projected
on its rest direction, over its rest length), and a spring of rest length ``L`` at strain ``e``
stores ``kappa * L**2 * (e**2 / 2 + beta * e**4 / 4)``: stiff where it is strained, which makes
the block stiffen as it is pressed deeper (depth 5.3 mm at 0.5 N, 24.7 mm at 6.2 N and 27.0 mm
at 7.5 N for a normal press at the centre; over a session of 20 presses the largest tip travel
between two static states is about 30 mm, like the paper's experimental phantom). On a finer
lattice the springs are softer, ``kappa`` scaling as the spacing to the power 1.1: at 4 mm the
centre press's depth stays within 2.5 % of the 5 mm lattice's from 1 to 7.5 N. The
energy is convex, so every load has exactly one equilibrium and the depth along the load rises
monotonically with the force (its derivative is ``f^T K^-1 f > 0``).

Parts of the block may be another silicone (:mod:`sim.twin.material_regions`: inclusions, a
top layer): the springs through them are scaled, as springs in series along each
(``Phantom.spring_scale``); without any, every spring is the block's. Nothing in the
linearised lattice stops a press at the table: a press whose tip would sink below it (softer
silicone under a strong press) is refused.

A curved block (:mod:`sim.twin.twin_shape`) stretches each column of nodes from the table to
its top; each spring then stores ``kappa * L0**2 * s * (e**2 / 2 + ...)``, ``L0`` its length
before the stretch and ``s`` its columns' stretch: the energy of a continuum cell ``s`` times
as tall (a taller column gives more along it and resists more across it), so the lattice
still behaves as one silicone whatever the shape.

A press is a dead load ``F * direction`` shared by a contact node (60 %) and its four neighbours
on the top surface, the rounded tip. Equilibria are found by nonlinear conjugate gradients
preconditioned with one sparse factorisation of the rest stiffness, shared by every solve.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.interpolate import PchipInterpolator

from core.errors import BadInput
from sim.twin.marker_layout import SPACING_M, MarkerLayout, lattice_axes, marker_nodes
from sim.twin.material_regions import Inclusion, Layer, check_regions, spring_scale
from sim.twin.twin_shape import TwinShape, check_one_silicone

# the 13 lattice directions of a node: 3 edges, 6 face diagonals, 4 body diagonals
_DIRECTIONS = ((1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, -1, 0), (1, 0, 1), (1, 0, -1),
               (0, 1, 1), (0, 1, -1), (1, 1, 1), (1, 1, -1), (1, -1, 1), (1, -1, -1))
_PATCH = ((0, 0), (1, 0), (-1, 0), (0, 1), (0, -1))   # the tip's contact node and neighbours
STIFFNESS_EXPONENT = 1.1    # kappa ~ spacing ** this keeps the block's depth under a press


@dataclass(frozen=True)
class PhantomSpec:
    """Geometry and material of the block (SI units)."""

    size: tuple[float, float, float] = (0.100, 0.100, 0.032)   # x, y, thickness (m)
    layers: int = 5                  # lattice nodes through the thickness
    stiffness: float = 6.494         # kappa (N/m): a spring's stiffness at small strain, on
    #                                  the 5 mm lattice (scaled to the lattice's spacing)
    stiffening: float = 5.0          # beta: the quartic term of the spring energy
    markers: MarkerLayout = MarkerLayout()   # 5 x 5 surface markers 20 mm apart, centred
    marker_radius: float = 0.0015    # 3 mm spheres: centre 1.5 mm above the surface
    tip_share: float = 0.6           # share of the load on the contact node (rest: neighbours)
    tol: float = 1e-4                # N: largest force component left unbalanced on any node
    #                                  (x, y or z; positions ~1 um)
    inclusions: tuple[Inclusion, ...] = ()   # spheres of another silicone
    layer: Layer | None = None       # the top of the block, another silicone
    shape: TwinShape | None = field(default=None, compare=False)   # a curved top; None: flat

    def __post_init__(self) -> None:
        check_regions(self.inclusions, self.layer, self.size)
        check_one_silicone(self.shape, self.inclusions, self.layer)


@dataclass
class LoadPath:
    """Equilibria of one press at increasing force levels (phantom frame, metres)."""

    forces: np.ndarray    # (K,) N, ascending, forces[0] == 0
    direction: np.ndarray  # (3,) unit vector of the load
    tip: np.ndarray       # (K, 3) the tip (load-weighted contact patch)
    markers: np.ndarray   # (K, M, 3) marker centres
    surface: np.ndarray   # (K, nx, ny, 3) top-layer nodes

    def interpolate(self, force: np.ndarray, what: str = "tip") -> np.ndarray:
        """``tip``, ``markers`` or ``surface`` at arbitrary forces (monotone cubic in force)."""
        values = getattr(self, what)
        f = np.clip(np.asarray(force, dtype=np.float64), self.forces[0], self.forces[-1])
        flat = values.reshape(len(self.forces), -1)
        out = PchipInterpolator(self.forces, flat, axis=0)(f)
        return out.reshape(f.shape + values.shape[1:])


class Phantom:
    """The lattice, its rest stiffness factorisation and static solves of presses."""

    def __init__(self, spec: PhantomSpec | None = None) -> None:
        self.spec = spec or PhantomSpec()
        lz = self.spec.size[2]
        xs, ys = lattice_axes(self.spec.size[:2], self.spec.markers)
        axes = (xs, ys, np.linspace(0.0, lz, self.spec.layers))
        self.nodes = (len(xs), len(ys), self.spec.layers)
        nx, ny, nz = self.nodes
        self.marker_ij = marker_nodes(self.spec.markers, xs, ys)   # (M, 2) (i, j): P00, P01, ..
        self.rest = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        self.grid = np.arange(nx * ny * nz).reshape(nx, ny, nz)
        self.springs = _springs(self.grid)
        stretch = None
        if self.spec.shape is not None:      # each column stretched from the table to the top
            flat_length = np.linalg.norm(self.rest[self.springs[:, 1]]
                                         - self.rest[self.springs[:, 0]], axis=1)
            column = self.spec.shape.top(self.rest[:, :2]) / lz
            self.rest[:, 2] *= column
            stretch = (column[self.springs[:, 0]] + column[self.springs[:, 1]]) / 2
        delta = self.rest[self.springs[:, 1]] - self.rest[self.springs[:, 0]]
        length = np.linalg.norm(delta, axis=1)
        free = self.rest[:, 2] > lz * 1e-9
        self.dof = np.full((len(self.rest), 3), -1, dtype=np.int64)
        self.dof[free] = np.arange(3 * int(free.sum())).reshape(-1, 3)
        self.n_dof = 3 * int(free.sum())
        # strain = A @ u: each spring's end displacements projected on its rest direction / L
        ends = np.concatenate([self.dof[self.springs[:, 0]], self.dof[self.springs[:, 1]]], 1)
        coef = np.concatenate([-delta, delta], axis=1) / (length**2)[:, None]
        coef[ends < 0] = 0.0
        ends = np.where(ends < 0, 0, ends)
        rows = np.repeat(np.arange(len(length)), 6)
        self._A = sp.csr_matrix((coef.ravel(), (rows, ends.ravel())),
                                shape=(len(length), self.n_dof))
        self._AT = self._A.T.tocsr()
        spec = self.spec
        self.spring_scale = spring_scale(self.rest[self.springs[:, 0]],
                                         self.rest[self.springs[:, 1]], spec.inclusions,
                                         spec.layer, spec.size, lz / (spec.layers - 1))
        self._energy = self.kappa * length**2 * self.spring_scale   # kappa * L^2 per spring
        if stretch is not None:   # a continuum's cells: volume x stretch, strain along L
            self._energy = self.kappa * flat_length**2 * stretch * self.spring_scale
        self._rest_k = (self._AT @ sp.diags(self._energy) @ self._A).tocsc()
        self.solves = 0
        self.iterations = 0

    # ------------------------------------------------------------------------- geometry

    @property
    def kappa(self) -> float:
        """The springs' stiffness (N/m) on this lattice: ``spec.stiffness`` at 5 mm."""
        ratio = self.spec.markers.spacing() / SPACING_M
        return self.spec.stiffness * (1.0 if abs(ratio - 1.0) < 1e-12
                                      else ratio ** STIFFNESS_EXPONENT)

    @property
    def n_markers(self) -> int:
        """How many surface markers the block carries."""
        return len(self.marker_ij)

    def top(self, i: int, j: int) -> int:
        """Node id of top-surface grid point (i along x, j along y)."""
        return int(self.grid[i, j, -1])

    def candidate_locations(self, margin: float = 0.020) -> np.ndarray:
        """(C, 2) top nodes a press may target: at least two lattice spacings from every
        marker (the tip's patch never touches one) and ``margin`` from the edges."""
        nx, ny, _ = self.nodes
        pos = self.rest[self.grid[:, :, -1]][..., :2]
        inner = ((np.abs(pos[..., 0]) <= self.spec.size[0] / 2 - margin)
                 & (np.abs(pos[..., 1]) <= self.spec.size[1] / 2 - margin))
        ii, jj = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
        far = np.ones((nx, ny), dtype=bool)
        for mi, mj in self.marker_ij:
            far &= np.maximum(np.abs(ii - mi), np.abs(jj - mj)) >= 2
        return np.argwhere(inner & far)

    def contact_point(self, ij: tuple[int, int]) -> np.ndarray:
        """Rest position of the tip at a location (the contact node)."""
        return self.rest[self.top(*ij)].copy()

    # ------------------------------------------------------------------------- statics

    def load_path(self, ij: tuple[int, int], direction: np.ndarray,
                  forces: np.ndarray) -> LoadPath:
        """Equilibria under ``F * direction`` on the tip patch at ``ij``, for each force.

        ``forces`` must ascend; 0 N (the rest state) is prepended when absent. Each solve
        starts from the cubic extrapolation of the previous equilibria (in force).
        """
        d = np.asarray(direction, dtype=np.float64)
        d = d / np.linalg.norm(d)
        levels = np.asarray(forces, dtype=np.float64)
        if levels[0] != 0.0:
            levels = np.concatenate([[0.0], levels])
        if np.any(np.diff(levels) <= 0):
            raise ValueError("force levels must ascend")
        unit = np.zeros(self.n_dof)
        for node, w in self._patch(ij):
            unit[self.dof[node]] += w * d
        states = [np.zeros(self.n_dof)]
        for k in range(1, len(levels)):
            known = slice(max(0, k - 4), k)
            weights = _extrapolation(levels[known], levels[k])
            guess = sum(w * u for w, u in zip(weights, states[known], strict=True))
            states.append(self.solve(levels[k] * unit, guess))
        obs = [self.observe(u, ij) for u in states]
        tips = np.array([o[0] for o in obs])
        self._check_above_table(ij, levels, tips)
        return LoadPath(forces=levels, direction=d, tip=tips,
                        markers=np.array([o[1] for o in obs]),
                        surface=np.array([o[2] for o in obs]))

    def solve(self, load: np.ndarray, guess: np.ndarray | None = None,
              max_iter: int = 500) -> np.ndarray:
        """Free-node displacements (n_dof,) in equilibrium with the nodal ``load``."""
        A, AT, c, beta = self._A, self._AT, self._energy, self.spec.stiffening
        u = np.zeros(self.n_dof) if guess is None else np.array(guess, dtype=np.float64)
        e = A @ u
        g = AT @ (c * e * (1.0 + beta * e * e)) - load
        self.solves += 1
        if np.abs(g).max() < self.spec.tol:
            return u
        z = self._rest_lu.solve(g)
        p, gz = -z, float((g * z).sum())
        for _ in range(max_iter):
            de = A @ p
            u_step = _line_search(e, de, c, beta, float((load * p).sum()))
            u += u_step * p
            e += u_step * de
            self.iterations += 1
            g_new = AT @ (c * e * (1.0 + beta * e * e)) - load
            if np.abs(g_new).max() < self.spec.tol:
                return u
            z_new = self._rest_lu.solve(g_new)
            gz_new = float((g_new * z_new).sum())
            polak = max(0.0, (gz_new - float((g_new * z).sum())) / gz)   # Polak-Ribiere+
            p = -z_new + polak * p
            z, gz = z_new, gz_new
        raise RuntimeError(f"phantom equilibrium not reached in {max_iter} iterations")

    def observe(self, u: np.ndarray, ij: tuple[int, int] | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Tip (3,) (NaN without ``ij``), marker centres (M, 3) and top surface (nx, ny, 3)."""
        pos = self.rest.copy()
        free = self.dof[:, 0] >= 0
        pos[free] += u.reshape(-1, 3)
        surface = pos[self.grid[:, :, -1]]
        normal = surface_normals(surface)
        mi, mj = self.marker_ij[:, 0], self.marker_ij[:, 1]
        markers = surface[mi, mj] + self.spec.marker_radius * normal[mi, mj]
        tip = np.full(3, np.nan)
        if ij is not None:
            tip = sum(w * pos[node] for node, w in self._patch(ij))
        return tip, markers, surface

    def rest_normal(self, ij: tuple[int, int]) -> np.ndarray:
        """The top surface's outward unit normal (3,) at a location, at rest."""
        return surface_normals(self.rest[self.grid[:, :, -1]])[ij]

    def _check_above_table(self, ij: tuple[int, int], levels: np.ndarray,
                           tips: np.ndarray) -> None:
        """Refuse a press whose tip sinks below the table (z < 0): far beyond what the
        lattice's linearised kinematics can carry. The uniform block keeps the tip about 3 mm
        above it at the twin's strongest presses; a region of softer silicone under it may not
        (the contact node itself may dip a little below the table before the tip does)."""
        below = np.flatnonzero(tips[:, 2] < 0.0)
        if below.size == 0:
            return
        k = int(below[0])
        spec = self.spec
        at = (self.contact_point(ij)[:2] + np.array(spec.size[:2]) / 2) * 1e3
        regions = [r.describe() for r in (*spec.inclusions, spec.layer)
                   if r is not None and r.ratio < 1.0]
        raise BadInput(None, f"a press of {levels[k]:.2f} N at ({at[0]:.0f}, {at[1]:.0f}) mm "
                       f"sinks the tip {-tips[k, 2] * 1e3:.1f} mm below the table, through the "
                       f"{spec.size[2] * 1e3:g} mm block: more than its lattice can carry"
                       + (f"; its softer silicone ({'; '.join(regions)}) is too soft under "
                          "the press: use a ratio nearer 1" if regions else ""))

    @cached_property
    def _rest_lu(self) -> spla.SuperLU:
        return spla.splu(self._rest_k, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                         options={"SymmetricMode": True})

    def _patch(self, ij: tuple[int, int]) -> list[tuple[int, float]]:
        share = (1.0 - self.spec.tip_share) / (len(_PATCH) - 1)
        return [(self.top(ij[0] + a, ij[1] + b), self.spec.tip_share if (a, b) == (0, 0)
                 else share) for a, b in _PATCH]


def surface_normals(surface: np.ndarray) -> np.ndarray:
    """Outward unit normals (nx, ny, 3) of a grid of top-surface points (nx, ny, 3)."""
    normal = np.cross(np.gradient(surface, axis=0), np.gradient(surface, axis=1))
    return normal / np.linalg.norm(normal, axis=-1, keepdims=True)


def _springs(grid: np.ndarray) -> np.ndarray:
    """(E, 2) node pairs joined along the 13 lattice directions."""
    shape = grid.shape
    pairs = []
    for step in _DIRECTIONS:
        src = tuple(slice(max(0, -s), n - max(0, s)) for s, n in zip(step, shape, strict=True))
        dst = tuple(slice(max(0, s), n - max(0, -s)) for s, n in zip(step, shape, strict=True))
        pairs.append(np.stack([grid[src].ravel(), grid[dst].ravel()], axis=1))
    return np.concatenate(pairs)


def _extrapolation(known: np.ndarray, at: float) -> np.ndarray:
    """Lagrange weights that extrapolate values known at ``known`` forces to force ``at``."""
    return np.array([np.prod([(at - xm) / (xj - xm) for m, xm in enumerate(known) if m != j])
                     for j, xj in enumerate(known)])


def _line_search(e: np.ndarray, de: np.ndarray, c: np.ndarray, beta: float,
                 load_step: float) -> float:
    """Exact step along a search direction: Newton on the energy's derivative (convex in a)."""
    cde = c * de
    cde2 = cde * de
    a = 0.0
    for _ in range(8):
        en = e + a * de
        e2 = en * en
        slope = float((cde * en * (1.0 + beta * e2)).sum()) - load_step
        curve = float((cde2 * (1.0 + 3.0 * beta * e2)).sum())
        step = slope / curve
        a -= step
        if abs(step) <= 1e-6 * max(abs(a), 1e-12):
            break
    return a

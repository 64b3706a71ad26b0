"""The surface mass-spring model (MSM) of the paper, and its reference explicit solver.

A single-layer surface of masses on a triangulated rectangular grid (the paper's: 32 x 32
masses over 100 x 100 mm): linear springs between neighbours along the rows, the columns and
one diagonal ((i, j) to (i + 1, j + 1)), each with its rest length (so the force depends on the
current length: large deflections are geometrically nonlinear), and a zero-length "fixed"
spring from every mass to its rest position. The grid has ``n_y`` rows of ``n`` masses, spaced
``h_x = size / (n - 1)`` along x and ``h_y = size_y / (n_y - 1)`` along y (the paper's 100/31 mm
both ways), so it covers the footprint [0, size] x [0, size_y] exactly. Mass (i, j) (row i,
column j, row-major index i n + j) rests at (x, y, z) = (j h_x, i h_y, 0); the surface normal
is +z and an indenting force points into the surface (negative z).

The reference solver integrates ``m a = f(x) + f_ext - c v`` explicitly (semi-implicit Euler,
time step ``dt``) until the paper's stability criterion holds on every mass: ``|v| < v_static``
and ``|f| < f_static`` (``f`` is the force of the springs and the load, without damping). It is
what the paper did; :mod:`sim.msm.msm_static` is the fast path that solves the same equilibrium.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from functools import cached_property
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from core.errors import BadInput
from sim.msm import paper
from sim.msm.msm_regions import check_map, mass_factors

# Edge families as (row offset, column offset): rows, columns, the one diagonal.
FAMILIES: tuple[tuple[int, int], ...] = ((0, 1), (1, 0), (1, 1))


class MSMError(BadInput):
    """The model's parameters (or a load) make the simulation fail: one clear line, exit 2."""

    def __init__(self, what: str) -> None:
        super().__init__("msm", what)

    def __reduce__(self) -> tuple:       # so it crosses from a worker process intact
        return MSMError, (self.what,)


@dataclass(frozen=True)
class MSMParams:
    """The MSM's parameters (SI units): the paper's by default.

    The grid: ``n`` masses along x over ``size``, ``n_y`` along y over ``size_y``; left out
    (None), the y ones are the x ones (a square: the paper's 32 x 32 over 100 mm, and what an
    older ``msm_params`` record of ``n`` and ``size`` alone means). Stored resolved, so a
    record always names both axes. :func:`sim.msm.msm_grid.grid_params` sizes a grid to a
    footprint. ``stiffness_map`` (rows of factors on the springs per region of the footprint,
    :mod:`sim.msm.msm_regions`) makes it stiffer in places; left out, it is uniform.
    """

    n: int = paper.GRID_N               # masses along x (per side of the square)
    size: float = paper.SIZE_M          # m, the surface's length along x
    mass: float = paper.MASS_KG         # kg per mass
    damping: float = paper.DAMPING      # N s/m: damping force -c v on each mass
    k_between: float = paper.K_BETWEEN  # N/m, springs between masses
    k_fixed: float = paper.K_FIXED      # N/m, zero-length springs to the rest positions
    dt: float = paper.DT_S              # s, explicit time step of the reference solver
    v_static: float = paper.V_STATIC    # m/s, stability criterion on every mass
    f_static: float = paper.F_STATIC    # N, stability criterion on every mass
    n_y: int | None = None              # masses along y (None: n)
    size_y: float | None = None         # m, the surface's width along y (None: size)
    stiffness_map: tuple[tuple[float, ...], ...] | None = None   # factors per region
    #                                     (sim.msm.msm_regions); None: uniform

    def __post_init__(self) -> None:
        if self.n_y is None:
            object.__setattr__(self, "n_y", self.n)
        if self.size_y is None:
            object.__setattr__(self, "size_y", self.size)
        for name in ("n", "n_y"):
            value = getattr(self, name)
            if not isinstance(value, int | np.integer) or isinstance(value, bool) or value < 2:
                raise MSMError(f"{name} must be an integer >= 2, got {value!r}")
        for name in ("size", "size_y", "mass", "damping", "k_between", "k_fixed", "dt",
                     "v_static", "f_static"):
            value = getattr(self, name)
            if not (isinstance(value, int | float | np.floating) and math.isfinite(value)
                    and value > 0):
                raise MSMError(f"{name} must be a finite positive number, got {value!r}")
        if self.stiffness_map is not None:
            try:
                object.__setattr__(self, "stiffness_map", check_map(self.stiffness_map))
            except BadInput as e:
                raise MSMError(e.what) from None

    @property
    def grid_rows(self) -> int:
        """``n_y`` as stored: the masses along y, the grid's rows (resolved, never None)."""
        if self.n_y is None:
            raise MSMError("n_y is unresolved")
        return self.n_y

    @property
    def width(self) -> float:
        """``size_y`` as stored: the surface's width along y (m; resolved, never None)."""
        if self.size_y is None:
            raise MSMError("size_y is unresolved")
        return self.size_y

    @property
    def spacing_x(self) -> float:
        """Rest length of the row springs, the masses' spacing along x (m)."""
        return self.size / (self.n - 1)

    @property
    def spacing_y(self) -> float:
        """Rest length of the column springs, the masses' spacing along y (m)."""
        return self.width / (self.grid_rows - 1)

    @property
    def footprint(self) -> tuple[float, float]:
        """(L, W): the surface's extent along x and y (m); it covers [0, L] x [0, W]."""
        return float(self.size), float(self.width)

    def as_dict(self) -> dict[str, Any]:
        """The fields by name (the stiffness map as rows of factors)."""
        return asdict(self)


class MSM:
    """Geometry and force kernels of one parameter set; positions are (N, 3) arrays in m."""

    def __init__(self, params: MSMParams | None = None) -> None:
        self.params = params or MSMParams()
        rows, cols = int(self.params.grid_rows), int(self.params.n)
        hx, hy = self.params.spacing_x, self.params.spacing_y
        self.rows, self.cols, self.N = rows, cols, rows * cols
        ii, jj = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
        self.rest = np.stack([jj * hx, ii * hy, np.zeros_like(ii, float)], -1).reshape(-1, 3)
        # hx hypot(dj, di hy / hx): on a square exactly the h hypot(di, dj) it always was
        self.rest_length = {(di, dj): hx * math.hypot(dj, di * hy / hx) for di, dj in FAMILIES}
        self._stiffness()

    def _stiffness(self) -> None:
        """The springs' constants: scalars on a uniform MSM; with a stiffness map, ``k_fixed``
        per mass (N, 1) and ``k_between`` per spring of each family (the mean of its two
        masses' factors)."""
        p = self.params
        self.k_fixed: float | np.ndarray = p.k_fixed
        self.k_between: dict[tuple[int, int], float | np.ndarray] = {
            fam: p.k_between for fam in FAMILIES}
        if p.stiffness_map is None:
            return
        factor = mass_factors(self.rest[:, :2], p.footprint, p.stiffness_map)
        self.k_fixed = p.k_fixed * factor[:, None]
        g, r, c = factor.reshape(self.rows, self.cols), self.rows, self.cols
        self.k_between = {(di, dj): p.k_between * 0.5 * (g[: r - di, : c - dj] + g[di:, dj:])
                          for di, dj in FAMILIES}

    @cached_property
    def dt_limit(self) -> float:
        """Explicit stability limit (s) at the rest state; see :func:`stability_limit`."""
        return stability_limit(self)

    # -- indexing -----------------------------------------------------------------------------
    def node(self, i: int, j: int) -> int:
        """Mass index of grid position (row i, column j)."""
        return int(i) * self.cols + int(j)

    def edges(self) -> np.ndarray:
        """(E, 2) mass indices of every between-mass spring (rows, columns, diagonals)."""
        r, c = self.rows, self.cols
        idx = np.arange(self.N).reshape(r, c)
        return np.vstack([np.c_[idx[: r - di, : c - dj].ravel(), idx[di:, dj:].ravel()]
                          for di, dj in FAMILIES])

    def triangles(self) -> np.ndarray:
        """(2 (rows - 1) (cols - 1), 3) triangles of the surface, split along the diagonal
        springs."""
        idx = np.arange(self.N).reshape(self.rows, self.cols)
        p, r, d, q = idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]
        return np.vstack([np.c_[p.ravel(), r.ravel(), d.ravel()],
                          np.c_[p.ravel(), d.ravel(), q.ravel()]]).astype(np.int32)

    # -- forces and energy --------------------------------------------------------------------
    def springs(self, g: np.ndarray):
        """Per family: ((di, dj), difference vectors, lengths) of the springs of grid ``g``."""
        r, c = self.rows, self.cols
        for di, dj in FAMILIES:
            d = g[di:, dj:] - g[: r - di, : c - dj]
            yield (di, dj), d, np.sqrt(np.einsum("...k,...k->...", d, d))

    def energy_forces(self, x: np.ndarray, f_ext: np.ndarray) -> tuple[float, np.ndarray]:
        """Potential energy (J, with the load's) and the force on every mass (N, 3), no damping."""
        return self._forces(x, f_ext, with_energy=True)

    def forces(self, x: np.ndarray, f_ext: np.ndarray) -> np.ndarray:
        """Force on every mass (N, 3): springs plus the load, without damping."""
        return self._forces(x, f_ext, with_energy=False)[1]

    def _forces(self, x: np.ndarray, f_ext: np.ndarray, with_energy: bool
                ) -> tuple[float, np.ndarray]:
        r, c = self.rows, self.cols
        disp = x - self.rest
        f = f_ext - self.k_fixed * disp
        fg = f.reshape(r, c, 3)
        energy = 0.0
        if with_energy:
            energy = 0.5 * _weighted_square(self.k_fixed, disp) - np.einsum(
                "ij,ij->", f_ext, x)
        for (di, dj), d, length in self.springs(x.reshape(r, c, 3)):
            stretch = length - self.rest_length[(di, dj)]
            kb = self.k_between[(di, dj)]
            if with_energy:
                energy += 0.5 * _weighted_square(kb, stretch)
            fs = (kb * stretch / length)[..., None] * d
            fg[: r - di, : c - dj] += fs
            fg[di:, dj:] -= fs
        return float(energy), f

    def load(self, node: int | np.ndarray, force: np.ndarray) -> np.ndarray:
        """External force array (N, 3) with ``force`` on one mass, or shared equally among
        the masses of an index array (a contact patch: the paper's n_n masses, F / n_n each)."""
        where = np.atleast_1d(node)
        f_ext = np.zeros((self.N, 3))
        f_ext[where] = np.asarray(force, dtype=float) / len(where)
        return f_ext

    # -- stiffness ----------------------------------------------------------------------------
    def edge_stiffness(self, x: np.ndarray, clamp: bool = False
                       ) -> dict[tuple[int, int], np.ndarray]:
        """Per family, the 3x3 tangent stiffness of each spring (rows, cols, 3, 3).

        ``k u u^T + k (1 - L0/L) (I - u u^T)``: the axial term and the geometric (tension)
        term, the exact Hessian of the spring energy. With ``clamp`` the geometric term of
        compressed springs is dropped, so every block is positive semi-definite and the
        assembled matrix (plus ``k_fixed I``) is positive definite whatever the state.
        """
        out = {}
        for fam, d, length in self.springs(x.reshape(self.rows, self.cols, 3)):
            kb = self.k_between[fam]
            u = d / length[..., None]
            geo = kb * (1.0 - self.rest_length[fam] / length)
            if clamp:
                geo = np.maximum(0.0, geo)
            k = (kb - geo)[..., None, None] * u[..., :, None] * u[..., None, :]
            k[..., [0, 1, 2], [0, 1, 2]] += geo[..., None]
            out[fam] = k
        return out

    # -- band storage ---------------------------------------------------------------------------
    @property
    def by_columns(self) -> bool:
        """Whether the band numbers the masses column by column: where the rows are longer
        than the columns, so the band is as narrow as the grid allows (a 48 x 26 grid: 83
        unknowns, not 149). The paper's square keeps row-major order."""
        return self.cols > self.rows

    @property
    def band_width(self) -> int:
        """Half-bandwidth of the tangent stiffness: masses numbered along the shorter side
        (:attr:`by_columns`), three unknowns each."""
        return 3 * (min(self.rows, self.cols) + 1) + 2

    @cached_property
    def band_order(self) -> np.ndarray | None:
        """The unknowns (3N,) in band order: ``K_band = K[order][:, order]``; None where the
        band keeps the masses' own row-major order."""
        if not self.by_columns:
            return None
        masses = np.arange(self.N).reshape(self.rows, self.cols).T.ravel()
        return (3 * masses[:, None] + np.arange(3)).ravel()

    def stiffness_band(self, x: np.ndarray | None = None, clamp: bool = False) -> np.ndarray:
        """Tangent stiffness at ``x`` (rest when None) in LAPACK upper band storage, unknowns
        in :attr:`band_order`.

        ``ab[bw + i - j, j] = K[i, j]`` for ``j - bw <= i <= j`` (``bw`` = :attr:`band_width`):
        the springs' blocks (:meth:`edge_stiffness`) plus ``k_fixed`` on the diagonal.
        """
        x = self.rest if x is None else x
        blocks = self.edge_stiffness(x, clamp)
        r, c = self.rows, self.cols
        k_fixed = np.broadcast_to(np.asarray(self.k_fixed, dtype=float).reshape(-1),
                                  (self.N,)).reshape(r, c)
        if self.by_columns:            # the transposed grid: family (di, dj) becomes (dj, di)
            blocks = {(dj, di): k.transpose(1, 0, 2, 3) for (di, dj), k in blocks.items()}
            r, c = c, r
            k_fixed = k_fixed.T
        N, bw = self.N, self.band_width
        ab = np.zeros((bw + 1, 3 * N))
        diag: np.ndarray = np.zeros((r, c, 3, 3))
        diag[..., [0, 1, 2], [0, 1, 2]] = k_fixed[..., None]
        for (di, dj), k in blocks.items():
            diag[: r - di, : c - dj] += k
            diag[di:, dj:] += k
            by_target: np.ndarray = np.zeros((r, c, 3, 3))
            by_target[di:, dj:] = k
            by_target = by_target.reshape(N, 3, 3)
            off = di * c + dj
            for a in range(3):
                for b in range(3):
                    ab[bw - 3 * off + a - b, 3 * off + b::3] = -by_target[off:, a, b]
        diag = diag.reshape(N, 3, 3)
        for a in range(3):
            for b in range(a, 3):
                ab[bw + a - b, b::3] = diag[:, a, b]
        return ab


def _weighted_square(k: float | np.ndarray, a: np.ndarray) -> float:
    """``sum(k a^2)`` over every element of ``a`` (2-D), ``k`` a scalar or one per row/spring."""
    if np.ndim(k) == 0:
        return float(k * np.einsum("ij,ij->", a, a))
    return float(np.einsum("ij,ij->", k * a, a))


# -- explicit integration (the paper's reference) ----------------------------------------------

def max_eigenfrequency(model: MSM, x: np.ndarray | None = None) -> float:
    """Largest angular eigenfrequency sqrt(lambda_max(K) / m) (rad/s) of the model at ``x``.

    Lanczos (``eigsh``) on the band of :meth:`MSM.stiffness_band` viewed as a sparse matrix:
    ~0.05 s, where LAPACK's banded eigensolver agrees to 1e-15 but takes ~0.6 s.
    """
    ab = model.stiffness_band(x)
    size, bw = ab.shape[1], model.band_width
    upper = sp.dia_matrix((ab, np.arange(bw, -1, -1)), shape=(size, size))
    k = (upper + sp.triu(upper, 1).T).tocsr()          # the band's symmetric whole
    lam = spla.eigsh(k, k=1, which="LA", return_eigenvectors=False, tol=1e-8)[0]
    return math.sqrt(lam / model.params.mass)


def stability_limit(model: MSM, x: np.ndarray | None = None) -> float:
    """Largest stable time step (s) of damped semi-implicit Euler at ``x`` (rest when None).

    A mode ``x'' = -w^2 x - g x'`` (``g = c/m``) stepped by semi-implicit Euler has the
    amplification matrix [[1 - w^2 dt^2, dt (1 - g dt)], [-w^2 dt, 1 - g dt]]: trace
    2 - g dt - w^2 dt^2, determinant 1 - g dt; it is stable iff w^2 dt^2 + 2 g dt < 4, i.e.
    dt < (sqrt(g^2 + 4 w^2) - g) / w^2, which is 2/w without damping.
    """
    w = max_eigenfrequency(model, x)
    g = model.params.damping / model.params.mass
    return (math.sqrt(g * g + 4 * w * w) - g) / (w * w)


def check_time_step(model: MSM) -> None:
    """Refuse a time step at or beyond the explicit stability limit of the rest state.

    Under load the stretched springs add geometric stiffness and the limit drops a little
    (the protocol's 7.5 N diverges at 0.95 of the rest limit); :func:`relax_explicit`
    catches that as it happens.
    """
    if model.params.dt >= model.dt_limit:
        raise MSMError(f"time step dt={model.params.dt:g} s is at or beyond the explicit "
                       f"stability limit {model.dt_limit:.4g} s of the rest state; use a "
                       "smaller dt")


def relax_explicit(
    model: MSM, x: np.ndarray, v: np.ndarray, f_ext: np.ndarray, *,
    v_tol: float | None = None, f_tol: float | None = None, max_steps: int = 200_000,
    check_every: int = 50,
) -> tuple[np.ndarray, np.ndarray, int]:
    """Integrate from (x, v) under ``f_ext`` until static; returns (x, v, time steps taken).

    Static means max per-mass |v| < v_tol and max per-mass |f| < f_tol (default: the paper's
    0.02 m/s and 0.02 N). Divergence (non-finite values, or mechanical energy rising above
    where it started: a damped system under a constant load only loses energy) and a run that
    is not static within ``max_steps`` end in :class:`MSMError`; no NaN state is returned.
    """
    p = model.params
    v_tol = p.v_static if v_tol is None else v_tol
    f_tol = p.f_static if f_tol is None else f_tol
    start = x
    x, v = x.copy(), v.copy()
    dt, c, m = p.dt, p.damping, p.mass
    e0 = None
    for step in range(max_steps + 1):
        if step % check_every == 0:
            energy, f = model.energy_forces(x, f_ext)
            total = energy + 0.5 * m * np.einsum("ij,ij->", v, v)
            e0 = total if e0 is None else e0
            if not math.isfinite(total) or total > e0 + 1e-6 + 1e-3 * abs(e0):
                raise MSMError(f"explicit integration diverged after {step} steps: energy "
                               f"grew from {e0:.4g} J to {total:.4g} J; dt={dt:g} s, stability "
                               f"limit {model.dt_limit:.4g} s at rest, "
                               f"{stability_limit(model, start):.4g} s at the start state")
        else:
            f = model.forces(x, f_ext)
        if step > 0 and max_norm(v) < v_tol and max_norm(f) < f_tol:
            return x, v, step
        if step == max_steps:
            break
        v += (dt / m) * (f - c * v)
        x += dt * v
    raise MSMError(f"explicit integration not static after {max_steps} steps of {dt:g} s "
                   f"(max |v| {max_norm(v):.3g} m/s, max |f| {max_norm(f):.3g} N)")


def simulate_reference(
    model: MSM, node: int, direction: np.ndarray, steps: int = 15, fmax: float = 7.5, *,
    v_tol: float | None = None, f_tol: float | None = None, max_steps: int = 200_000,
) -> tuple[np.ndarray, list[int]]:
    """The paper's protocol for one sequence by explicit integration.

    The force on mass ``node`` grows to ``fmax`` along ``direction`` in ``steps`` equal steps;
    each step runs from the previous static state (velocities carried over) to the stability
    criterion. Returns the states (steps + 1, N, 3), the rest state first, and the number of
    time steps each force step took.
    """
    check_time_step(model)
    direction = unit(direction)
    x = model.rest.copy()
    v = np.zeros_like(x)
    states, counts = [x.copy()], []
    for t in range(1, steps + 1):
        x, v, count = relax_explicit(model, x, v, model.load(node, direction * fmax * t / steps),
                                     v_tol=v_tol, f_tol=f_tol, max_steps=max_steps)
        states.append(x.copy())
        counts.append(count)
    return np.stack(states), counts


def unit(direction: np.ndarray) -> np.ndarray:
    """``direction`` scaled to length 1 (a zero or non-finite vector is refused)."""
    d = np.asarray(direction, dtype=float)
    norm = float(np.linalg.norm(d))
    if d.shape != (3,) or not math.isfinite(norm) or norm == 0:
        raise MSMError(f"force direction must be a finite non-zero 3-vector, got {direction!r}")
    return d / norm


def max_norm(a: np.ndarray) -> float:
    """Largest per-mass vector norm of an (N, 3) or flat (3N,) array."""
    a3 = a.reshape(-1, 3)
    return float(np.sqrt(np.einsum("ij,ij->i", a3, a3).max()))

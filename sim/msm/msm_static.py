"""The fast path: the MSM's static equilibrium solved directly instead of integrated in time.

The equilibrium of the springs and the load is the minimum of the potential energy
(:meth:`sim.msm.msm.MSM.energy_forces`). We minimise it with L-BFGS whose initial inverse
Hessian is a banded Cholesky factor of the tangent stiffness: with masses numbered along the
shorter side the half-bandwidth is 3 (n + 1) + 2 unknowns for n masses per side (101 on the
paper's 32 x 32 grid, 83 on a 48 x 26 one), so LAPACK factors the 3072 x 3072 matrix in ~3 ms
and applies it in ~0.1 ms (single precision: it only guides iterations whose forces are
evaluated in double precision). A backtracking (Armijo) line search on the energy keeps every
iteration downhill. A factor is reused across iterations and force steps and refreshed where
convergence slows or a step had to be cut (the first load on the flat, tension-free surface
needs that most); each force step starts from the linear extrapolation of the two previous
equilibria. On the paper's protocol that is ~0.6 factorizations and ~6.5 iterations per state.
Every solve ends with the largest per-mass force below ``tol`` (1e-6 N by default) or raises
:class:`sim.msm.msm.MSMError`; it never returns a non-finite state.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import lapack

from sim.msm import paper
from sim.msm.blas_threads import blas_threads
from sim.msm.msm import MSM, MSMError, max_norm, unit

DEFAULT_TOL = paper.STATIC_TOL_N   # N: largest force on any mass at an accepted equilibrium
MEMORY = 8                # L-BFGS pairs kept
REFACTOR_AFTER = 6        # refresh the factor at the next step when a step took more iterations
REFACTOR_EVERY = 12       # ... and within a step after this many iterations on one factor
SHORT_STEP = 0.25         # ... and at once after a line search had to cut the step below this
ENERGY_ROUNDOFF = 1e-12   # relative resolution of the summed energy in the line search
MAX_ITER = 500


@dataclass
class SolveStats:
    """What one or more static solves cost."""

    iterations: int = 0
    factorizations: int = 0
    evaluations: int = 0
    per_step: list[int] = field(default_factory=list)
    max_residual: float = 0.0      # N, largest per-mass force left by any accepted solve


class BandedTangent:
    """Cholesky factors of the tangent stiffness in band storage (:meth:`MSM.stiffness_band`)."""

    def __init__(self, model: MSM) -> None:
        self.model = model
        self.bw = model.band_width

    def factor(self, x: np.ndarray, convex: bool = False) -> np.ndarray:
        """Cholesky factor (band storage) of the tangent at ``x``, for use as a preconditioner.

        Single precision (quicker to factor and apply, and the iterations it guides
        are evaluated in double precision, so the equilibrium is as exact); double precision
        where single precision cannot factor it. The exact Hessian where it is positive
        definite (Newton-like convergence); where compressed springs make it indefinite, or
        with ``convex``, the tangent without their negative geometric stiffness (always
        positive definite).
        """
        for clamp in ((True,) if convex else (False, True)):
            ab = self.model.stiffness_band(x, clamp)
            chol, info = lapack.spbtrf(ab.astype(np.float32), lower=0, overwrite_ab=1)
            if info == 0:
                return chol
            chol, info = lapack.dpbtrf(ab, lower=0, overwrite_ab=1)
            if info == 0:
                return chol
        raise MSMError(f"tangent stiffness not positive definite (dpbtrf info {info})")


class StaticSolver:
    """Equilibria of one model, one after another, reusing the factor and curvature pairs."""

    def __init__(self, model: MSM, tol: float = DEFAULT_TOL, max_iter: int = MAX_ITER) -> None:
        check_tol(tol)
        self.model, self.tol, self.max_iter = model, tol, max_iter
        self.tangent = BandedTangent(model)
        self.stats = SolveStats()
        self._chol: np.ndarray | None = None
        self._rest_chol: np.ndarray | None = None     # every sequence starts here
        self._last_iterations = 0

    def reset(self) -> None:
        """Forget the factor (start of a new sequence)."""
        self._chol = None
        self._last_iterations = 0

    def solve(self, x0: np.ndarray, f_ext: np.ndarray) -> np.ndarray:
        """The equilibrium under ``f_ext`` nearest ``x0`` (N, 3): max per-mass |f| < tol."""
        x = np.array(x0, dtype=float).ravel()
        stale = self._chol is None or self._last_iterations > REFACTOR_AFTER
        s_mem: list[np.ndarray] = []
        y_mem: list[np.ndarray] = []
        energy, g = self._evaluate(x, f_ext)
        on_factor = 0
        short = False
        for it in range(self.max_iter):
            left = max_norm(g)
            if left < self.tol:
                self._last_iterations = it
                self.stats.iterations += it
                self.stats.per_step.append(it)
                self.stats.max_residual = max(self.stats.max_residual, left)
                return x.reshape(-1, 3)
            if stale or on_factor >= REFACTOR_EVERY:
                self._refactor(x, convex=short)
                s_mem, y_mem, on_factor, stale = [], [], 0, False
            p = self._direction(g, s_mem, y_mem)
            slope = float(g @ p)
            if slope >= 0:          # not a descent direction: restart from a fresh factor
                self._refactor(x)
                s_mem, y_mem, on_factor = [], [], 0
                p = self._direction(g, s_mem, y_mem)
                slope = float(g @ p)
            x_new, e_new, g_new, step = self._line_search(x, energy, slope, p, f_ext)
            # A much shortened step means the factor no longer models the energy here (the
            # first load on the flat, tension-free surface; a soft surface near wrinkling):
            # refresh it at the new point, without the softening of compressed springs.
            stale = short = step < SHORT_STEP
            on_factor += 1
            s, y = x_new - x, g_new - g
            sy = float(s @ y)
            if sy > 1e-12 * math.sqrt(float(s @ s) * float(y @ y)):
                s_mem.append(s)
                y_mem.append(y)
                if len(s_mem) > MEMORY:
                    s_mem.pop(0)
                    y_mem.pop(0)
            x, energy, g = x_new, e_new, g_new
        raise MSMError(f"static solve did not converge in {self.max_iter} iterations "
                       f"(max |f| {max_norm(g):.3g} N > tol {self.tol:g} N)")

    def _refactor(self, x: np.ndarray, convex: bool = False) -> None:
        x = x.reshape(-1, 3)
        at_rest = not convex and np.array_equal(x, self.model.rest)
        if at_rest and self._rest_chol is not None:
            self._chol = self._rest_chol
            return
        self._chol = self.tangent.factor(x, convex)
        self.stats.factorizations += 1
        if at_rest:
            self._rest_chol = self._chol

    def _evaluate(self, x: np.ndarray, f_ext: np.ndarray) -> tuple[float, np.ndarray]:
        """Energy and its gradient (minus the forces), flat; refuses non-finite values."""
        energy, f = self.model.energy_forces(x.reshape(-1, 3), f_ext)
        self.stats.evaluations += 1
        if not (math.isfinite(energy) and np.isfinite(f).all()):
            raise MSMError("static solve produced non-finite energy or forces (load or "
                           "springs extreme)")
        return energy, -f.ravel()

    def _direction(self, g: np.ndarray, s_mem: list, y_mem: list) -> np.ndarray:
        """L-BFGS two-loop recursion with the banded Cholesky solve as the initial inverse."""
        q = g.copy()
        alphas = []
        rhos = [1.0 / float(y @ s) for s, y in zip(s_mem, y_mem, strict=True)]
        for s, y, rho in zip(reversed(s_mem), reversed(y_mem), reversed(rhos), strict=True):
            a = rho * float(s @ q)
            q -= a * y
            alphas.append(a)
        r = self._band_solve(q)
        for s, y, rho, a in zip(s_mem, y_mem, rhos, reversed(alphas), strict=True):
            r += (a - rho * float(y @ r)) * s
        return -r

    def _band_solve(self, q: np.ndarray) -> np.ndarray:
        """``K^-1 q`` by the banded Cholesky factor (its unknowns in the model's band order)."""
        chol = self._chol
        if chol is None:
            raise MSMError("no factor to solve with: factor the tangent first")
        solve = lapack.spbtrs if chol.dtype == np.float32 else lapack.dpbtrs
        order = self.model.band_order
        if order is None:
            return solve(chol, q.astype(chol.dtype), lower=0)[0].astype(np.float64)
        r = np.empty_like(q)
        r[order] = solve(chol, q[order].astype(chol.dtype), lower=0)[0]
        return r

    def _line_search(self, x: np.ndarray, energy: float, slope: float, p: np.ndarray,
                     f_ext: np.ndarray) -> tuple[np.ndarray, float, np.ndarray, float]:
        """Backtracking from the full step until the energy drops enough (Armijo).

        Near the solution the decrease falls below the round-off of the energy (~1e-12 of
        it); within that band a step counts as no worse.
        """
        step = 1.0
        slack = ENERGY_ROUNDOFF * max(abs(energy), 1e-6)
        for _ in range(40):
            x_new = x + step * p
            e_new, g_new = self._evaluate(x_new, f_ext)
            if e_new <= energy + 1e-4 * step * slope + slack:
                break
            step *= 0.5
        # After 40 halvings the energy no longer resolves the decrease (round-off): take the
        # tiny step; the next iteration refreshes the factor.
        return x_new, e_new, g_new, step


def solve_path(solver: StaticSolver, loads: Iterable[np.ndarray]) -> Iterator[np.ndarray]:
    """Equilibria (N, 3) under each external force array of ``loads`` in turn, from rest.

    Each solve starts from the extrapolation of the two previous equilibria (the first from
    the rest state), so a growing load is followed like the paper's quasi-static press.
    """
    solver.reset()
    prev = x = solver.model.rest
    with blas_threads(1):
        for f_ext in loads:
            guess = x if x is prev else 2 * x - prev
            prev, x = x, solver.solve(guess, f_ext)
            yield x


def simulate_sequence(
    model: MSM, node: int | np.ndarray, direction: np.ndarray, steps: int = 15,
    fmax: float = 7.5, tol: float = DEFAULT_TOL, solver: StaticSolver | None = None,
) -> np.ndarray:
    """The paper's protocol for one sequence by static solves: states (steps + 1, N, 3).

    Force step t puts ``t * fmax / steps`` along ``direction`` on mass ``node`` (or shared
    among the masses of an array: a contact patch); each solve starts from the extrapolation
    of the two previous equilibria. A ``solver`` passed in (to reuse its rest factor across
    sequences) must be of ``model`` and have tolerance ``tol``.
    """
    if solver is None:
        solver = StaticSolver(model, tol)
    elif solver.model is not model or solver.tol != tol:
        raise ValueError(f"solver of another model or tolerance (tol {solver.tol:g} N, "
                         f"asked {tol:g} N)")
    direction = unit(direction)
    forces = [direction * fmax * t / steps for t in range(1, steps + 1)]
    states = np.empty((steps + 1, model.N, 3))
    states[0] = model.rest
    where = np.atleast_1d(node)
    label = f"mass {int(where[0])}" if len(where) == 1 else f"masses {where.tolist()}"
    done = 0                       # steps solved so far: a failure is at step done + 1
    try:
        for x in solve_path(solver, (model.load(node, f) for f in forces)):
            done += 1
            states[done] = x
    except MSMError as e:
        raise MSMError(f"{label}, force {np.round(forces[done], 4).tolist()} N (step "
                       f"{done + 1}): {e.what}") from None
    return states


def check_tol(tol: float) -> None:
    """Refuse a static tolerance that is not a finite positive force."""
    if not (math.isfinite(tol) and tol > 0):
        raise MSMError(f"tolerance must be a finite positive force, got {tol!r}")


def residual(model: MSM, x: np.ndarray, f_ext: np.ndarray) -> float:
    """Largest per-mass force (N) at ``x``: zero at an exact equilibrium."""
    return max_norm(model.forces(x, f_ext).ravel())


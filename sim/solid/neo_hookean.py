"""The hyperelastic candidate: the block as a compressible neo-Hookean solid, pressed by Newton
steps.

The strain energy per unit rest volume is ``mu/2 (tr(F^T F) - 3) - mu ln J + lambda/2 ln^2 J``
(``F = I + grad u``, ``J = det F``), with each element's Lame parameters from the same
:class:`~sim.solid.elasticity.Material` as the linear solid (so at small loads both give the
same field). Its first Piola-Kirchhoff stress is
``P = mu (F - F^-T) + lambda ln J F^-T`` and the tangent
``dP = mu dF + (mu - lambda ln J) F^-T dF^T F^-T + lambda (F^-T : dF) F^-T``; scikit-fem
assembles both forms (trilinear hexahedra, the linear solid's basis), the stress fields
computed once per step at the quadrature points.

A press is a sequence of loads (one per state): each is solved from the last one's field by
Newton steps, the tangent factorised anew each step and a step halved while it would turn an
element inside out; a load that still inverts one, or does not converge, is refused in one
line. This is many
factorisations a state where the linear solid needs none: ``benchmarks/bench_solid.py
--hyperelastic`` measures the trade.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from skfem import BilinearForm, LinearForm, asm
from skfem.helpers import ddot, det, grad, identity, inv, mul, transpose

from sim.solid.elasticity import Elasticity, Material

STEP_TOL = 1e-6      # a Newton step below this share of the field's size: converged
MOST_STEPS = 25      # Newton steps a load may take
HALVINGS = 12        # a step that inverts an element is halved at most this often


@LinearForm
def _internal(v, w):                  # noqa: ANN001, ANN202 (scikit-fem's form signature)
    return ddot(w["P"], grad(v))


@BilinearForm
def _tangent(u, v, w):                # noqa: ANN001, ANN202
    fit, c, mu, lam = w["Fit"], w["c"], w["mu"], w["lam"]
    du = grad(u)
    dp = mu * du + c * mul(fit, mul(transpose(du), fit)) + lam * ddot(fit, du) * fit
    return ddot(dp, grad(v))


@dataclass(frozen=True)
class Solved:
    """A press solved: the field at each load (T, N) and the Newton steps each took (T,)."""

    fields: np.ndarray
    steps: np.ndarray


class NeoHookean:
    """A block's neo-Hookean solid: the linear solid's mesh, basis and fixed bottom."""

    def __init__(self, elasticity: Elasticity, material: Material) -> None:
        self.elasticity = elasticity
        lam, mu = material.lame()
        points = elasticity.basis.X.shape[1]
        self._lam = np.repeat(lam[:, None], points, axis=1)     # (E, quadrature points)
        self._mu = np.repeat(mu[:, None], points, axis=1)

    def internal(self, u: np.ndarray) -> np.ndarray:
        """(N,) the internal forces of the field ``u`` (N,) m."""
        return asm(_internal, self.elasticity.basis, P=self._stress(u)["P"])

    def tangent(self, u: np.ndarray) -> sp.csr_matrix:
        """The tangent stiffness (N, N) at the field ``u``."""
        return asm(_tangent, self.elasticity.basis, **self._stress(u)).tocsr()

    def press(self, loads: np.ndarray, partial: bool = False) -> Solved:
        """The fields under each of ``loads`` (T, N) N in turn, each from the last; with
        ``partial``, those solved before the first load that fails (none refused)."""
        u = np.zeros(self.elasticity.basis.N)
        fields, steps = [], []
        for t, load in enumerate(loads):
            try:
                steps.append(self._newton(u, load, t))
            except ValueError:
                if not partial:
                    raise
                break
            fields.append(u.copy())
        return Solved(np.array(fields).reshape(len(fields), len(u)), np.array(steps, int))

    def _newton(self, u: np.ndarray, load: np.ndarray, t: int) -> int:
        """Newton steps on ``u`` (in place) until it carries ``load``, each step halved while
        it would turn an element inside out; how many steps it took."""
        free = self.elasticity.free
        for step in range(1, MOST_STEPS + 1):
            stress = self._stress(u)                  # once a step, for both forms
            residual = asm(_internal, self.elasticity.basis, P=stress["P"]) - load
            k = asm(_tangent, self.elasticity.basis, **stress).tocsr()[free][:, free].tocsc()
            du = spla.splu(k, permc_spec="COLAMD").solve(-residual[free])
            u[free] += self._admissible(u, du)
            if np.linalg.norm(du) <= STEP_TOL * np.linalg.norm(u):
                return step
        raise ValueError(f"load {t}: Newton did not converge in {MOST_STEPS} steps")

    def _admissible(self, u: np.ndarray, du: np.ndarray) -> np.ndarray:
        """``du`` (on the free unknowns), halved until ``u + du`` turns no element inside out;
        refused where :data:`HALVINGS` halvings do not do it."""
        trial = u.copy()
        for _ in range(HALVINGS):
            trial[self.elasticity.free] = u[self.elasticity.free] + du
            if self._least_j(trial) > 0.0:
                return du
            du = 0.5 * du
        raise ValueError("an element turned inside out (J <= 0): the load is too deep for "
                         "this mesh")

    def _least_j(self, u: np.ndarray) -> float:
        """The smallest volume ratio J over the quadrature points of ``u``."""
        return float(det(self._deformation(u)).min())

    def _deformation(self, u: np.ndarray) -> np.ndarray:
        """F = I + grad u at the quadrature points (3, 3, E, Q)."""
        g = self.elasticity.basis.interpolate(u)
        return np.asarray(identity(g) + grad(g))

    def _stress(self, u: np.ndarray) -> dict[str, np.ndarray]:
        """P, F^-T, mu - lambda ln J, mu and lambda at the quadrature points of ``u`` (an
        inverted element refused)."""
        f = self._deformation(u)
        j = det(f)
        if np.any(j <= 0.0):
            raise ValueError("an element turned inside out (J <= 0)")
        fit = transpose(inv(f))
        ln_j = np.log(j)
        return {"P": self._mu * (f - fit) + self._lam * ln_j * fit, "Fit": fit,
                "c": self._mu - self._lam * ln_j, "mu": self._mu, "lam": self._lam}

"""Linear elasticity of the block, assembled once by scikit-fem and weighted per element.

The stiffness of an isotropic solid is ``K = sum_e (lambda_e K^lambda_e + mu_e K^mu_e)``:
linear in each element's Lame parameters. scikit-fem assembles the two unit forms
(``div u div v`` and ``2 eps(u) : eps(v)``) once, element by element (trilinear hexahedra,
2 x 2 x 2 Gauss points); a material (a modulus per element, one Poisson ratio) is then a
weighting of those element blocks, with no new assembly. The bottom face is fixed (the table),
so ``K`` is kept on the free degrees of freedom and factorised once per material: every load
after that is a back-substitution.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from skfem import Basis, BilinearForm, ElementHex1, ElementVector, MeshHex
from skfem.helpers import ddot, div, sym_grad

from core.bounds import Bound

POISSON = Bound(0.0, 0.49, unit="", why="a solid's Poisson ratio (silicone is near 0.5; "
                "0.49 keeps trilinear elements from locking)")


@BilinearForm
def _dilatation(u, v, w):          # noqa: ANN001, ANN202 (scikit-fem's form signature)
    return div(u) * div(v)


@BilinearForm
def _shear(u, v, w):               # noqa: ANN001, ANN202
    return 2.0 * ddot(sym_grad(u), sym_grad(v))


@dataclass(frozen=True)
class Material:
    """Young's modulus per element (Pa) and one Poisson ratio."""

    modulus: np.ndarray     # (E,) Pa
    poisson: float

    def lame(self) -> tuple[np.ndarray, np.ndarray]:
        """(lambda, mu) per element."""
        e, nu = self.modulus, self.poisson
        return e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), e / (2.0 * (1.0 + nu))


class Elasticity:
    """The block's unit forms per element, its fixed bottom, and a factorised stiffness."""

    def __init__(self, mesh: MeshHex, symmetry: bool = False) -> None:
        """``symmetry``: also hold the faces x = 0 and y = 0 as mirror planes (their normal
        displacement 0): a quarter of a block pressed at its corner, for the Hertz check."""
        self.mesh = mesh
        self.basis = Basis(mesh, ElementVector(ElementHex1()), intorder=2)
        self._lam = _form(_dilatation, self.basis)
        self._mu = _form(_shear, self.basis)
        bottom = mesh.p[2].min()
        fixed = [self.basis.get_dofs(lambda x: np.isclose(x[2], bottom)).all()]
        if symmetry:
            fixed += [self.basis.get_dofs(lambda x: np.isclose(x[0], 0.0)).nodal["u^1"],
                      self.basis.get_dofs(lambda x: np.isclose(x[1], 0.0)).nodal["u^2"]]
        self.free = np.setdiff1d(np.arange(self.basis.N), np.concatenate(fixed))

    @property
    def n_elements(self) -> int:
        """How many hexahedra the block has."""
        return int(self.mesh.t.shape[1])

    def element_centres(self) -> np.ndarray:
        """(E, 3) the centre of each element (m)."""
        return self.mesh.p[:, self.mesh.t].mean(axis=1).T

    def stiffness(self, material: Material) -> sp.csc_matrix:
        """K on the free degrees of freedom for ``material``."""
        lam, mu = material.lame()
        k = self._lam.weighted(lam) + self._mu.weighted(mu)
        return k[self.free][:, self.free].tocsc()

    def factorise(self, material: Material) -> Solver:
        """The stiffness of ``material`` factorised once, for many loads."""
        lu = spla.splu(self.stiffness(material), permc_spec="COLAMD", diag_pivot_thresh=0.0,
                      options={"SymmetricMode": True})
        return Solver(lu, self.free, self.basis.N)


@dataclass
class Solver:
    """Back-substitutions on one factorised stiffness: full displacement vectors out."""

    lu: spla.SuperLU
    free: np.ndarray
    n_dofs: int

    def solve(self, loads: np.ndarray) -> np.ndarray:
        """(n_dofs, k) displacements (m) for (n_dofs, k) nodal loads (N); the fixed ones 0."""
        out = np.zeros((self.n_dofs, loads.shape[1]))
        out[self.free] = self.lu.solve(np.ascontiguousarray(loads[self.free]))
        return out


@dataclass
class _ElementBlocks:
    """One unit form's element blocks, ready to be weighted per element."""

    rows: np.ndarray
    cols: np.ndarray
    data: np.ndarray        # (local pairs, E)
    shape: tuple[int, int]

    def weighted(self, weight: np.ndarray) -> sp.csr_matrix:
        """``sum_e weight_e K_e`` (weight (E,))."""
        values = (self.data * weight[None, :]).ravel()
        return sp.coo_matrix((values, (self.rows, self.cols)), shape=self.shape).tocsr()


def _form(form: BilinearForm, basis: Basis) -> _ElementBlocks:
    """The element blocks of ``form`` on ``basis`` (scikit-fem's COO data, elements last)."""
    coo = form.coo_data(basis)
    rows, cols = coo.indices
    return _ElementBlocks(rows=rows, cols=cols, data=coo.data.reshape(-1, basis.nelems),
                          shape=(basis.N, basis.N))

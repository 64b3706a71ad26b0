"""The surface MSM: its truth values, its kernels against independent ones, the fast static
path against the reference explicit integration, symmetry, and the numerical extremes."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from helpers.msm_reference import forces_by_edge_loop
from scipy.linalg import eig_banded

from sim.msm.msm import (
    MSM,
    MSMError,
    MSMParams,
    max_eigenfrequency,
    relax_explicit,
    simulate_reference,
    stability_limit,
    unit,
)
from sim.msm.msm_static import StaticSolver, residual, simulate_sequence

MODEL = MSM()
CENTRE = MODEL.node(16, 16)


@pytest.fixture(scope="module")
def centre_normal() -> np.ndarray:
    """The paper's check: the normal force on mass (16, 16), 0.5 N steps up to 7.5 N."""
    return simulate_sequence(MODEL, CENTRE, [0, 0, -1], steps=15, fmax=7.5, tol=1e-9)


def _disp(states: np.ndarray) -> np.ndarray:
    return np.linalg.norm(states - MODEL.rest, axis=-1)


# -- truth values ------------------------------------------------------------------------------

def test_paper_displacements_of_a_centred_normal_load(centre_normal):
    d = _disp(centre_normal).max(axis=1) * 1e3      # mm
    assert d[1] == pytest.approx(5.05, abs=0.01)     # 0.5 N
    assert d[15] == pytest.approx(29.5, abs=0.05)    # 7.5 N
    assert np.all(np.diff(d) > 0)
    # the loaded mass moves most, straight down
    assert np.all(_disp(centre_normal[1:]).argmax(axis=1) == CENTRE)


def test_geometry_of_the_grid():
    h = 0.1 / 31
    assert MODEL.N == 1024 and MODEL.params.spacing_x == pytest.approx(h)
    assert np.allclose(MODEL.rest[MODEL.node(31, 31)], [0.1, 0.1, 0.0])
    edges = MODEL.edges()
    assert len(edges) == 31 * 32 * 2 + 31 * 31                   # rows, columns, one diagonal
    d = np.linalg.norm(MODEL.rest[edges[:, 1]] - MODEL.rest[edges[:, 0]], axis=1)
    assert set(np.round(d / h, 9)) == {1.0, round(np.sqrt(2), 9)}
    assert len(MODEL.triangles()) == 2 * 31 * 31


def test_forces_against_an_edge_loop_and_the_energy_gradient():
    rng = np.random.default_rng(0)
    x = MODEL.rest + rng.normal(0, 1e-3, MODEL.rest.shape)
    f_ext = MODEL.load(100, [0.2, -0.1, -1.0])
    energy, f = MODEL.energy_forces(x, f_ext)
    assert np.allclose(f, forces_by_edge_loop(MODEL, x, f_ext), atol=1e-12)
    v = rng.normal(size=x.shape)
    eps = 1e-7
    slope = (MODEL.energy_forces(x + eps * v, f_ext)[0]
             - MODEL.energy_forces(x - eps * v, f_ext)[0]) / (2 * eps)
    assert slope == pytest.approx(-(f * v).sum(), rel=1e-6)


def test_tangent_band_is_the_force_jacobian():
    """The band storage, expanded to the full symmetric matrix, against finite differences."""
    rng = np.random.default_rng(1)
    x = MODEL.rest * 1.05 + rng.normal(0, 2e-4, MODEL.rest.shape)   # every spring stretched
    ab, bw = MODEL.stiffness_band(x), MODEL.band_width
    k = np.zeros((3 * MODEL.N, 3 * MODEL.N))
    for off in range(bw + 1):
        i = np.arange(k.shape[0] - off)
        k[i, i + off] = k[i + off, i] = ab[bw - off, off:]
    for _ in range(3):
        v = rng.normal(size=x.shape)
        eps = 1e-7
        jv = -(MODEL.forces(x + eps * v, 0 * x) - MODEL.forces(x - eps * v, 0 * x)) / (2 * eps)
        assert np.allclose(jv.ravel(), k @ v.ravel(), atol=1e-5 * np.abs(k).max())
    # the largest eigenvalue the stability limit uses, against LAPACK's banded eigensolver
    top = eig_banded(ab, eigvals_only=True, select="i", select_range=(len(k) - 1,) * 2)[0]
    assert max_eigenfrequency(MODEL, x) ** 2 * MODEL.params.mass == pytest.approx(top,
                                                                                 rel=1e-10)


# -- fast path ---------------------------------------------------------------------------------

def test_fast_path_residual_below_1e6_newton(centre_normal):
    solver = StaticSolver(MODEL)
    states = simulate_sequence(MODEL, MODEL.node(5, 27), unit([0.4, -0.3, -1.0]),
                               solver=solver)
    d = unit([0.4, -0.3, -1.0])
    left = [residual(MODEL, states[t], MODEL.load(MODEL.node(5, 27), d * 0.5 * t))
            for t in range(1, 16)]
    assert max(left) < 1e-6
    assert solver.stats.max_residual == pytest.approx(max(left), rel=1e-9)   # every step
    assert residual(MODEL, centre_normal[15], MODEL.load(CENTRE, [0, 0, -7.5])) < 1e-9


def test_symmetry_of_a_centred_normal_load(centre_normal):
    """What truly holds for a normal load on mass (16, 16).

    Exact: the mirror across the diagonal line x = y through the loaded mass (it maps rows to
    columns and every diagonal spring onto itself). Approximate: point symmetry about the
    loaded mass (exact on an unbounded grid; the edges, 16 masses away on one side and 15 on
    the other, break it), best near the load. Not at all: the mirror across x = const (it
    would flip the diagonals).
    """
    for t in (1, 15):
        u = (centre_normal[t] - MODEL.rest).reshape(32, 32, 3)
        mirrored = u.transpose(1, 0, 2)[..., [1, 0, 2]]
        assert np.abs(u - mirrored).max() < 1e-10
        assert _point_error(u, 6) < 1e-6                     # m: < 1 um within 6 masses
        assert _point_error(u, 15) > 3 * _point_error(u, 3)  # the edges break it
        a = np.arange(-6, 7)
        flipped = u[16 + a[:, None], 16 - a[None, :]] * [-1, 1, 1]
        assert np.abs(u[16 + a[:, None], 16 + a[None, :]] - flipped).max() > 1e-4


def _point_error(u: np.ndarray, radius: int) -> float:
    """Largest departure from point symmetry about mass (16, 16) within ``radius`` masses."""
    a = np.arange(-radius, radius + 1)
    here = u[16 + a[:, None], 16 + a[None, :]]
    there = u[16 - a[:, None], 16 - a[None, :]] * [-1, -1, 1]
    return float(np.abs(here - there).max())


# -- reference explicit solver -----------------------------------------------------------------

def test_reference_agrees_with_fast_path_on_a_small_grid():
    """A 8 x 8 grid (same spacing, springs and masses), the whole protocol, tightened criterion."""
    small = MSM(MSMParams(n=8, size=7 * 0.1 / 31))
    node, d = small.node(3, 4), unit([0.3, 0.2, -1.0])
    ref, counts = simulate_reference(small, node, d, steps=5, fmax=2.5, v_tol=1e-5, f_tol=1e-5)
    fast = simulate_sequence(small, node, d, steps=5, fmax=2.5)
    assert np.abs(np.linalg.norm(ref - fast, axis=-1)).max() < 1e-5       # 0.01 mm
    assert min(counts) > 10


def test_reference_agrees_with_fast_path_on_the_paper_grid():
    """One 0.5 N step on the real grid: within 0.01 mm with a tightened criterion; with the
    paper's criterion (0.02 m/s, 0.02 N) the reference stops ~0.03 mm short."""
    d = unit([0.3, 0.2, -1.0])
    node = MODEL.node(10, 20)
    fast = simulate_sequence(MODEL, node, d, steps=1, fmax=0.5, tol=1e-9)[1]
    tight, _ = simulate_reference(MODEL, node, d, steps=1, fmax=0.5, v_tol=2e-4, f_tol=2e-4)
    paper, counts = simulate_reference(MODEL, node, d, steps=1, fmax=0.5)
    assert np.linalg.norm(tight[1] - fast, axis=1).max() < 1e-5
    paper_error = np.linalg.norm(paper[1] - fast, axis=1).max()
    assert 1e-6 < paper_error < 1e-4
    assert 50 < counts[0] < 1000            # time steps of 0.1 ms to reach the criterion


# -- extremes ----------------------------------------------------------------------------------

def test_ten_times_the_force_converges_to_a_checked_equilibrium():
    load = MODEL.load(CENTRE, [0, 0, -75.0])
    x = StaticSolver(MODEL).solve(MODEL.rest, load)
    assert residual(MODEL, x, load) < 1e-6
    assert 0.15 < _disp(x).max() < 0.3                # ~213 mm: the mass is pulled far out
    assert np.isfinite(x).all()


def test_corner_loads_converge():
    for i, j in ((0, 0), (31, 31), (0, 31)):
        node, d = MODEL.node(i, j), unit([0.5, 0.5, -1.0])
        states = simulate_sequence(MODEL, node, d)
        assert residual(MODEL, states[-1], MODEL.load(node, 7.5 * d)) < 1e-6
        assert _disp(states[-1]).argmax() == node


@pytest.mark.parametrize("k_between,k_fixed", [(1000.0, 1.0), (1.0, 1000.0)])
def test_stiffness_ratio_1000_converges(k_between, k_fixed):
    model = MSM(MSMParams(k_between=k_between, k_fixed=k_fixed))
    node = model.node(16, 16)
    states = simulate_sequence(model, node, [0.3, 0, -1], steps=3, fmax=7.5)
    assert residual(model, states[-1], model.load(node, 7.5 * unit([0.3, 0, -1]))) < 1e-6
    if k_fixed == 1000.0:   # the fixed springs carry it: nearly F / k_fixed
        assert _disp(states[-1])[node] == pytest.approx(7.5 / (1000 + 6), rel=0.01)


def test_stability_limit_is_the_real_limit():
    """dt just below the computed limit settles; just above it diverges with a clear error."""
    limit = stability_limit(MODEL)
    assert 8e-4 < limit < 8.5e-4          # 0.82 ms against the paper's 0.1 ms step
    rng = np.random.default_rng(0)
    x0 = MODEL.rest + rng.normal(0, 1e-6, MODEL.rest.shape)
    v0 = np.zeros_like(x0)
    below = MSM(dataclasses.replace(MODEL.params, dt=0.98 * limit))
    x, _, _ = relax_explicit(below, x0, v0, 0 * x0, v_tol=1e-9, f_tol=1e-9, max_steps=5000)
    assert np.abs(x - MODEL.rest).max() < 1e-6
    above = MSM(dataclasses.replace(MODEL.params, dt=1.02 * limit))
    with pytest.raises(MSMError, match="diverged"):
        relax_explicit(above, x0, v0, 0 * x0, v_tol=1e-9, f_tol=1e-9, max_steps=5000)


def test_reference_refuses_a_time_step_beyond_the_limit_and_settles_near_it():
    limit = stability_limit(MODEL)
    with pytest.raises(MSMError, match="stability limit"):
        simulate_reference(MSM(dataclasses.replace(MODEL.params, dt=1.1 * limit)), CENTRE,
                           [0, 0, -1], steps=1)
    near = MSM(dataclasses.replace(MODEL.params, dt=0.9 * limit))
    states, _ = simulate_reference(near, CENTRE, [0, 0, -1], steps=3, fmax=1.5)
    fast = simulate_sequence(MODEL, CENTRE, [0, 0, -1], steps=3, fmax=1.5)
    assert np.isfinite(states).all()
    assert np.linalg.norm(states - fast, axis=-1).max() < 1e-4


def test_reference_that_cannot_settle_ends_in_a_clear_error():
    soft = MSM(MSMParams(k_between=100.0, k_fixed=0.1))    # ratio 1000: minutes to settle
    with pytest.raises(MSMError, match="not static after 200 steps"):
        simulate_reference(soft, CENTRE, [0, 0, -1], steps=1, max_steps=200)


@pytest.mark.parametrize("field,value", [("k_fixed", 0.0), ("mass", -1.0), ("dt", float("nan")),
                                         ("n", 1)])
def test_bad_parameters_are_refused(field, value):
    with pytest.raises(MSMError, match=field):
        MSMParams(**{field: value})


def test_bad_direction_is_refused():
    with pytest.raises(MSMError, match="direction"):
        simulate_sequence(MODEL, CENTRE, [0, 0, 0])


def test_a_solver_of_another_tolerance_or_model_is_refused():
    """simulate_sequence handed a solver of another tolerance or model refuses it, rather than
    silently solving to the solver's tolerance."""
    solver = StaticSolver(MODEL, tol=1e-3)
    with pytest.raises(ValueError, match="tolerance"):
        simulate_sequence(MODEL, CENTRE, [0, 0, -1], steps=1, tol=1e-8, solver=solver)
    with pytest.raises(ValueError, match="another model"):
        simulate_sequence(MSM(), CENTRE, [0, 0, -1], steps=1, tol=1e-3, solver=solver)
    states = simulate_sequence(MODEL, CENTRE, [0, 0, -1], steps=1, tol=1e-3, solver=solver)
    assert residual(MODEL, states[1], MODEL.load(CENTRE, [0, 0, -7.5])) < 1e-3


def test_non_finite_forces_at_finite_energy_are_refused():
    """Two neighbouring masses on one point: the spring between them has no direction (NaN
    force) while its energy is finite."""
    x = MODEL.rest.copy()
    x[MODEL.node(5, 6)] = x[MODEL.node(5, 5)]
    with np.errstate(divide="ignore", invalid="ignore"), pytest.raises(MSMError,
                                                                       match="non-finite"):
        StaticSolver(MODEL)._evaluate(x.ravel(), MODEL.load(3, [0, 0, -1]))

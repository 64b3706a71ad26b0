"""The twin's volumetric phantom: equilibrium, monotone stiffening force-depth, calibration."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.phantom_springs import nodal_forces

from sim.twin.marker_layout import MarkerLayout
from sim.twin.phantom import Phantom, PhantomSpec

LEVELS = np.array([0.25, 0.5, 1.0, 2.0, 4.0, 6.2, 7.5])


@pytest.fixture(scope="module")
def phantom() -> Phantom:
    return Phantom()


@pytest.fixture(scope="module")
def centre_path(phantom: Phantom):
    return phantom.load_path((10, 10), np.array([0.0, 0.0, -1.0]), LEVELS)


def test_equilibrium_balances_the_load(phantom: Phantom) -> None:
    d = np.array([0.3, -0.2, -1.0])
    d /= np.linalg.norm(d)
    load = np.zeros(phantom.n_dof)
    node = phantom.top(8, 12)
    load[phantom.dof[node]] = 5.0 * d
    u = phantom.solve(load)
    forces = nodal_forces(phantom, u)
    free = phantom.dof[:, 0] >= 0
    applied = np.zeros_like(phantom.rest)
    applied[node] = 5.0 * d
    # every free node is balanced, and the table carries the whole load
    assert np.abs(forces[free] + applied[free]).max() < 2 * phantom.spec.tol
    np.testing.assert_allclose(forces[~free].sum(axis=0), 5.0 * d, atol=1e-3)


def test_force_depth_rises_monotonically_and_stiffens(centre_path) -> None:
    depth = -(centre_path.tip[:, 2] - centre_path.tip[0, 2]) * 1e3      # mm
    assert np.all(np.diff(depth) > 0)
    slope = np.diff(depth) / np.diff(centre_path.forces)                # mm per N
    assert np.all(np.diff(slope) < 0)                                   # stiffening
    # the paper's phantom: a few mm at 0.5 N, 25-30 mm at 6-7.5 N
    assert 4.0 < depth[2] < 7.0
    assert 22.0 < depth[-2] < 28.0
    assert 25.0 < depth[-1] < 30.0


def test_markers_follow_the_surface(phantom: Phantom, centre_path) -> None:
    rest = centre_path.markers[0]
    assert np.allclose(rest[:, 2], phantom.spec.size[2] + phantom.spec.marker_radius)
    np.testing.assert_allclose(rest[[0, 4, 20, 24], :2] * 1e3,
                               [[-40, -40], [40, -40], [-40, 40], [40, 40]], atol=1e-9)
    drop = rest[:, 2] - centre_path.markers[-1][:, 2]
    # the marker pressed under (the centre one) sinks most; its neighbours follow; the corners
    # barely move (they even bulge up a little, the material pushed aside)
    assert drop.argmax() == 12
    assert np.all(drop[[7, 11, 13, 17]] > 0.04 * drop[12])
    assert np.abs(drop[[0, 4, 20, 24]]).max() < 0.02 * drop[12]


OBLIQUE = np.array([np.sin(np.radians(20)), 0.0, -np.cos(np.radians(20))])


def test_oblique_press_depth_monotonic(phantom: Phantom) -> None:
    path = phantom.load_path((6, 14), OBLIQUE, LEVELS)
    along = (path.tip - path.tip[0]) @ OBLIQUE
    assert np.all(np.diff(along) > 0)
    assert np.all(np.diff(-(path.tip[:, 2] - path.tip[0, 2])) > 0)
    assert (path.tip[-1] - path.tip[0])[0] > 0                      # pushed along +x as well


def test_interpolation_between_states_is_the_direct_solve(phantom: Phantom) -> None:
    """The twin's truth between its 0.5 N states is interpolated: halfway between the levels
    it solves, the interpolation is the equilibrium solved there, to a few um (linear
    interpolation is off by up to 0.17 mm at the tip and 70 um at 1.25 N)."""
    levels = np.concatenate([[0.25], np.arange(0.5, 7.01, 0.5), [7.3]])   # as the twin's
    path = phantom.load_path((6, 14), OBLIQUE, levels)
    mids = 0.5 * (path.forces[1:] + path.forces[:-1])
    direct = phantom.load_path((6, 14), OBLIQUE, mids)
    for what in ("tip", "markers"):
        error = np.linalg.norm(path.interpolate(mids, what) - getattr(direct, what)[1:],
                               axis=-1).reshape(len(mids), -1).max(axis=1)
        assert error[0] < 1e-4                         # 0 .. 0.25 N: the softest, ~45-75 um
        assert np.all(error[1:][mids[1:] < 1.0] < 25e-6)
        assert np.all(error[mids > 1.0] < 10e-6)


def test_locations_keep_clear_of_markers(phantom: Phantom) -> None:
    cand = phantom.candidate_locations()
    assert len(cand) > 20
    gap = np.abs(cand[:, None, :] - phantom.marker_ij[None]).max(axis=2).min(axis=1)
    assert gap.min() >= 2


def test_stiffer_material_presses_less() -> None:
    soft = Phantom().load_path((10, 10), [0, 0, -1], np.array([2.0]))
    stiff = Phantom(PhantomSpec(stiffness=13.0)).load_path((10, 10), [0, 0, -1],
                                                           np.array([2.0]))
    assert (stiff.tip[0, 2] - stiff.tip[-1, 2]) < (soft.tip[0, 2] - soft.tip[-1, 2])


def test_a_dense_grid_gets_a_finer_lattice_closed_by_the_block_edges() -> None:
    """6 x 6 markers 12 mm apart: a 3 mm lattice laid from the markers, every marker on a
    node, the block's edges at +-50 mm closing cells between 1.5 and 4.5 mm, and presses
    between four markers still two spacings clear of each."""
    ph = Phantom(PhantomSpec(markers=MarkerLayout(rows=6, cols=6, pitch=0.012)))
    xs = ph.rest[ph.grid[:, 0, -1], 0]
    assert xs[0] == -0.05 and xs[-1] == 0.05
    cells = np.diff(xs)
    np.testing.assert_allclose(cells[1:-1], 0.003, atol=1e-12)
    assert np.all((cells >= 0.0015) & (cells <= 0.0045))
    at = ph.rest[ph.grid[ph.marker_ij[:, 0], ph.marker_ij[:, 1], -1]]
    grid = at[:, :2].reshape(6, 6, 2)
    np.testing.assert_allclose(grid[0, :, 0] * 1e3, [-30, -18, -6, 6, 18, 30], atol=1e-9)
    np.testing.assert_allclose(grid[:, 0, 1] * 1e3, [-30, -18, -6, 6, 18, 30], atol=1e-9)
    cand = ph.candidate_locations()
    pos = ph.rest[ph.grid[cand[:, 0], cand[:, 1], -1], :2]
    inside = np.all(np.abs(pos) < 0.030, axis=1)              # within the marker grid
    assert inside.sum() >= 9
    gap = np.abs(cand[:, None, :] - ph.marker_ij[None]).max(axis=2).min(axis=1)
    assert gap.min() >= 2


def test_a_finer_lattice_keeps_the_blocks_depth() -> None:
    """The springs scale with the spacing (kappa ~ h^1.1): a normal press at the centre of
    the 4 mm lattice (5 x 5 markers 16 mm apart) sinks within 3 % of the 5 mm lattice's
    from 1 to 7.5 N; with kappa unscaled it would sink 13 % less."""
    fine = Phantom(PhantomSpec(markers=MarkerLayout(pitch=0.016)))
    np.testing.assert_allclose(np.diff(fine.rest[fine.grid[:, 0, -1], 0])[1:-1], 0.004)
    assert fine.kappa < Phantom().kappa
    levels = np.array([1.0, 2.0, 4.0, 6.2, 7.5])

    def depth(ph: Phantom) -> np.ndarray:
        c = ph.nodes[0] // 2
        tip = ph.load_path((c, c), [0, 0, -1], levels).tip[:, 2]
        return tip[0] - tip[1:]

    ratio = depth(fine) / depth(Phantom())
    assert np.all(np.abs(ratio - 1) < 0.03), ratio

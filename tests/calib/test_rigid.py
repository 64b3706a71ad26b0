"""Rigid-body fit of the indenter cluster against known poses and scipy's align_vectors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from calib.rigid import cluster_reference, fit_rigid
from core.errors import BadInput
from sync.sync_params import SyncParams

# An asymmetric 4-marker cluster (metres), like an indenter's marker tree.
CLUSTER = np.array([[0.0, 0.0, 0.0], [0.045, 0.0, 0.0], [0.0, 0.030, 0.0], [0.012, 0.015, 0.038]])
MAX_RMS = SyncParams().max_fit_rms_m      # sync's tolerance of a cluster fit


def _poses(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    rot = Rotation.random(n, random_state=seed).as_matrix()
    return rot, rng.uniform(-0.3, 0.3, size=(n, 3))


def _observe(rot: np.ndarray, trans: np.ndarray, ref: np.ndarray = CLUSTER) -> np.ndarray:
    return np.einsum("tij,mj->tmi", rot, ref) + trans[:, None]


def test_recovers_known_poses_exactly() -> None:
    rot, trans = _poses(50, seed=1)
    fit = fit_rigid(CLUSTER, _observe(rot, trans), MAX_RMS)
    np.testing.assert_allclose(fit.rotation, rot, atol=1e-12)
    np.testing.assert_allclose(fit.translation, trans, atol=1e-12)
    assert np.all(fit.rms < 1e-12) and not fit.poor.any()
    assert (fit.n_markers == 4).all()


def test_three_of_four_markers_suffice() -> None:
    rot, trans = _poses(40, seed=2)
    obs = _observe(rot, trans)
    hidden = np.arange(40) % 4
    obs[np.arange(40), hidden] = np.nan
    fit = fit_rigid(CLUSTER, obs, MAX_RMS)
    assert (fit.n_markers == 3).all()
    np.testing.assert_allclose(fit.rotation, rot, atol=1e-12)
    tip = np.array([0.01, 0.02, -0.08])
    np.testing.assert_allclose(fit.apply(tip), rot @ tip + trans, atol=1e-12)


def test_matches_scipy_align_vectors_on_noisy_markers() -> None:
    rng = np.random.default_rng(3)
    rot, trans = _poses(30, seed=3)
    obs = _observe(rot, trans) + rng.normal(0, 0.3e-3, size=(30, 4, 3))
    fit = fit_rigid(CLUSTER, obs, MAX_RMS)
    for k in range(30):
        ref_c = CLUSTER - CLUSTER.mean(axis=0)
        obs_c = obs[k] - obs[k].mean(axis=0)
        want, _ = Rotation.align_vectors(obs_c, ref_c)
        np.testing.assert_allclose(fit.rotation[k], want.as_matrix(), atol=1e-9)
    # noise of 0.3 mm per coordinate: RMS residual per marker about sqrt(3 * 2/4) * 0.3 mm
    assert 0.2e-3 < np.median(fit.rms) < 0.5e-3


def test_collinear_markers_are_flagged() -> None:
    line = np.array([[0.0, 0.0, 0.0], [0.02, 0.0, 0.0], [0.05, 0.0001, 0.0], [0.0, 0.03, 0.0]])
    rot, trans = _poses(5, seed=4)
    obs = _observe(rot, trans, line)
    obs[:, 3] = np.nan                      # the three markers left are nearly on a line
    fit = fit_rigid(line, obs, MAX_RMS)
    assert fit.ill_conditioned.all() and fit.poor.all()
    full = fit_rigid(line, _observe(rot, trans, line), MAX_RMS)
    assert not full.ill_conditioned.any()


def test_too_few_markers_give_no_pose() -> None:
    rot, trans = _poses(3, seed=5)
    obs = _observe(rot, trans)
    obs[:, :2] = np.nan
    fit = fit_rigid(CLUSTER, obs, MAX_RMS)
    assert not fit.valid.any()
    assert np.isnan(fit.rotation).all() and np.isnan(fit.apply(np.zeros(3))).all()


def test_large_residual_is_poor() -> None:
    rot, trans = _poses(4, seed=6)
    obs = _observe(rot, trans)
    obs[:, 2] += 0.005                      # one marker 5 mm off (a swap or a reflection)
    fit = fit_rigid(CLUSTER, obs, MAX_RMS, drop_outlier=False)
    assert fit.poor.all() and not fit.ill_conditioned.any()


def test_an_outlying_marker_is_dropped() -> None:
    rot, trans = _poses(6, seed=9)
    obs = _observe(rot, trans)
    obs[:, 1] += 0.005
    fit = fit_rigid(CLUSTER, obs, MAX_RMS)
    assert not fit.poor.any() and (fit.n_markers == 3).all()
    np.testing.assert_allclose(fit.rotation, rot, atol=1e-12)
    obs[:, [2, 3]] = obs[:, [3, 2]]         # and a swap: no 3-subset fits, stays poor
    assert fit_rigid(CLUSTER, obs, MAX_RMS).poor.all()


def test_the_refit_with_the_smallest_residual_wins() -> None:
    """Marker 3 off by 4 mm: the full fit is poor, and dropping marker 0 already passes the
    limit (0.9 mm), but only dropping marker 3 gives the true pose."""
    rot, trans = _poses(1, seed=3)
    obs = _observe(rot, trans)
    obs[:, 3] += 0.004 * rot[0] @ (np.ones(3) / np.sqrt(3))
    without_0 = obs.copy()
    without_0[:, 0] = np.nan
    assert fit_rigid(CLUSTER, without_0, MAX_RMS, drop_outlier=False).rms[0] < 1e-3
    fit = fit_rigid(CLUSTER, obs, MAX_RMS)
    assert not fit.poor[0] and fit.n_markers[0] == 3 and fit.rms[0] < 1e-12
    np.testing.assert_allclose(fit.rotation, rot, atol=1e-12)


def test_cluster_reference_recovers_the_shape() -> None:
    rng = np.random.default_rng(7)
    rot, trans = _poses(200, seed=7)
    obs = _observe(rot, trans) + rng.normal(0, 0.1e-3, size=(200, 4, 3))
    obs[::3, 1] = np.nan                    # incomplete frames are skipped
    ref = cluster_reference(obs)
    dist = np.linalg.norm(ref[:, None] - ref[None], axis=2)
    true = np.linalg.norm(CLUSTER[:, None] - CLUSTER[None], axis=2)
    np.testing.assert_allclose(dist, true, atol=3e-5)
    np.testing.assert_allclose(ref.mean(axis=0), 0, atol=1e-12)
    # the body frame is right-handed: the signed volume of the markers keeps its sign
    volume = np.linalg.det(np.stack([ref[1] - ref[0], ref[2] - ref[0], ref[3] - ref[0]]))
    true_volume = np.linalg.det(np.stack([CLUSTER[i] - CLUSTER[0] for i in (1, 2, 3)]))
    assert np.sign(volume) == np.sign(true_volume) != 0
    # the axes' signs come from the markers' order: marker 0 on the positive side of x and y
    assert ref[0, 0] > 0 and ref[0, 1] > 0


def test_cluster_reference_is_the_same_frame_however_the_cluster_was_held() -> None:
    """The body frame is fixed by the markers, not by the pose or LAPACK's sign choices: the
    same cluster seen in two sets of poses gives the same body coordinates."""
    a = cluster_reference(_observe(*_poses(20, seed=11)))
    b = cluster_reference(_observe(*_poses(20, seed=12)))
    np.testing.assert_allclose(a, b, atol=1e-9)
    # and it is the true shape up to one rotation (the body frame's), no reflection
    u, _, vt = np.linalg.svd(a.T @ (CLUSTER - CLUSTER.mean(axis=0)))
    assert np.linalg.det(u @ vt) > 0


def test_cluster_reference_needs_a_complete_frame() -> None:
    rot, trans = _poses(5, seed=8)
    obs = _observe(rot, trans)
    obs[:, 0] = np.nan
    with pytest.raises(BadInput, match="pivot.tsv"):
        cluster_reference(obs, source="pivot.tsv")


def test_robust_reweighting_resists_heavy_tailed_noise() -> None:
    """Gamma-distributed residual lengths (0.18 +- 0.22 mm, like Qualisys): the reweighted fit
    puts a point 11 cm away (the tip) closer to the truth than plain least squares."""
    rng = np.random.default_rng(10)
    rot, trans = _poses(3000, seed=10)
    length = rng.gamma((0.18 / 0.22) ** 2, 0.22**2 / 0.18 * 1e-3, (3000, 4))
    direction = rng.normal(size=(3000, 4, 3))
    direction /= np.linalg.norm(direction, axis=2, keepdims=True)
    obs = _observe(rot, trans) + length[..., None] * direction
    tip = np.array([0.0, 0.0, -0.11])
    truth = rot @ tip + trans

    def err(fit):
        return np.sqrt(np.mean(np.sum((fit.apply(tip) - truth) ** 2, axis=1)))

    plain = err(fit_rigid(CLUSTER, obs, MAX_RMS))
    robust = err(fit_rigid(CLUSTER, obs, MAX_RMS, robust_scale=0.3e-3))
    assert robust < 0.95 * plain
    exact = fit_rigid(CLUSTER, _observe(rot, trans), MAX_RMS, robust_scale=0.3e-3)
    np.testing.assert_allclose(exact.rotation, rot, atol=1e-12)

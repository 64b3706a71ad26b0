"""Pivot calibration against a known tip offset, and against an independent sphere fit."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from calib.pivot import pivot_calibrate, rotation_spread_deg
from calib.rigid import cluster_reference, fit_rigid
from core.errors import BadInput
from sync.sync_params import SyncParams

CLUSTER = np.array([[0.0, 0.0, 0.0], [0.045, 0.0, 0.0], [0.0, 0.030, 0.0], [0.012, 0.015, 0.038]])
TIP = np.array([0.004, -0.006, -0.110])      # body frame, metres
PIVOT = np.array([0.12, -0.05, 0.80])        # lab frame
MAX_RMS = SyncParams().max_fit_rms_m         # sync's tolerance of a cluster fit
MIN_ROTATION = SyncParams().min_pivot_rotation_deg   # sync's least pivot rotation


def _tilts(n: int, seed: int, max_deg: float = 30.0, axes: str = "xy") -> np.ndarray:
    rng = np.random.default_rng(seed)
    ang = np.zeros((n, 3))
    for a in axes:
        ang[:, "xyz".index(a)] = rng.uniform(-max_deg, max_deg, n)
    ang[:, 2] += rng.uniform(-180, 180) if "z" not in axes else 0.0
    return Rotation.from_euler("xyz", ang, degrees=True).as_matrix()


def _poses(rot: np.ndarray) -> np.ndarray:
    return PIVOT - rot @ TIP                 # t_k so that R_k tip + t_k = pivot


def test_exact_poses_give_the_tip() -> None:
    rot = _tilts(50, seed=1)
    res = pivot_calibrate(rot, _poses(rot), min_rotation_deg=MIN_ROTATION)
    np.testing.assert_allclose(res.tip_body, TIP, atol=1e-12)
    np.testing.assert_allclose(res.pivot_lab, PIVOT, atol=1e-12)
    assert res.rms < 1e-12 and res.n_poses == 50
    assert res.rotation_spread_deg > 10


def test_noisy_markers_through_the_rigid_fit() -> None:
    rng = np.random.default_rng(2)
    rot = _tilts(2000, seed=2)
    trans = _poses(rot)
    markers = np.einsum("tij,mj->tmi", rot, CLUSTER) + trans[:, None]
    markers += rng.normal(0, 0.2e-3, markers.shape)
    ref = cluster_reference(markers)
    fit = fit_rigid(ref, markers, MAX_RMS)
    res = pivot_calibrate(fit.rotation, fit.translation, min_rotation_deg=MIN_ROTATION)
    # our body frame differs from the true one by a rigid motion: map our tip into it
    to_true = fit_rigid(ref, CLUSTER[None], MAX_RMS)
    tip_true_frame = to_true.apply(res.tip_body)[0]
    assert np.linalg.norm(tip_true_frame - TIP) < 0.2e-3
    assert np.linalg.norm(res.pivot_lab - PIVOT) < 0.2e-3
    assert 0.05e-3 < res.rms < 1e-3


def test_agrees_with_an_independent_sphere_fit() -> None:
    """Cluster origins lie on a sphere about the pivot; its algebraic fit gives the pivot."""
    rng = np.random.default_rng(3)
    rot = _tilts(500, seed=3, max_deg=35)
    trans = _poses(rot) + rng.normal(0, 0.1e-3, (500, 3))
    res = pivot_calibrate(rot, trans, min_rotation_deg=MIN_ROTATION)
    # |t - c|^2 = r^2  ->  2 t.c + (r^2 - |c|^2) = |t|^2, linear in (c, r^2 - |c|^2)
    a = np.column_stack([2 * trans, np.ones(len(trans))])
    sol, *_ = np.linalg.lstsq(a, (trans**2).sum(axis=1), rcond=None)
    centre = sol[:3]
    radius = np.sqrt(sol[3] + centre @ centre)
    assert np.linalg.norm(res.pivot_lab - centre) < 0.3e-3
    assert abs(np.linalg.norm(res.tip_body) - radius) < 0.3e-3


def test_no_rotation_is_refused_with_the_file_name() -> None:
    rot = np.repeat(np.eye(3)[None], 100, axis=0)
    trans = _poses(rot) + np.random.default_rng(4).normal(0, 1e-4, (100, 3))
    with pytest.raises(BadInput, match=r"pivot_3d\.tsv: .*too little rotation"):
        pivot_calibrate(rot, trans, source="pivot_3d.tsv", min_rotation_deg=MIN_ROTATION)


def test_rotation_about_one_axis_is_refused() -> None:
    rot = _tilts(200, seed=5, axes="x")
    with pytest.raises(BadInput, match="too little rotation"):
        pivot_calibrate(rot, _poses(rot), source="p.tsv", min_rotation_deg=MIN_ROTATION)
    spread = rotation_spread_deg(rot)
    assert spread[0] > 10 and spread[1] < 1e-6


def test_too_few_poses_and_nan_poses() -> None:
    rot = _tilts(30, seed=6)
    trans = _poses(rot)
    trans[5:] = np.nan
    with pytest.raises(BadInput, match="5 usable"):
        pivot_calibrate(rot, trans, source="p.tsv", min_rotation_deg=MIN_ROTATION)

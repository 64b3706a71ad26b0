"""Using a trained model: Predictor and the ONNX export give the network's answers, and refuse
inputs they cannot answer."""

from __future__ import annotations

import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch
from click.testing import CliRunner
from helpers.cgnn_data import dent_fold

from pipeline.cli import cli
from train import Predictor
from train.model.config import CGNNConfig
from train.training.checkpoint import load_checkpoint, model_from
from train.training.train_params import TrainInputs, TrainOptions, TrainParams
from train.training.train_stage import run_train


def _trained(d: Path, **kw) -> tuple[Path, np.ndarray, np.ndarray]:
    """A small model trained one epoch on the dent data: (run, a state's points, a press)."""
    data, splits = dent_fold(d, folds=1)
    cfg = CGNNConfig(edge_widths=((16, 16),) * 3, disp_widths=(32,), force_widths=(16, 8, 8),
                     **kw)
    run_train(TrainInputs(data, splits), d / "run",
              TrainParams(TrainOptions(epochs=1, batch=8), cfg, "cpu"))
    with h5py.File(data) as f:
        points, tip = f["states/points"][3], f["states/tip"][3]
    return d / "run", points, np.r_[tip, tip - [0, 0, 1e-3]].astype(np.float32)


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> tuple[Path, np.ndarray, np.ndarray]:
    """The paper's network: press-independent, so a scene's features are cached."""
    return _trained(tmp_path_factory.mktemp("pred"))


@pytest.fixture(scope="module")
def nocond_run(tmp_path_factory) -> tuple[Path, np.ndarray, np.ndarray]:
    """Without C (noCond): its traced graphs have no condition input."""
    return _trained(tmp_path_factory.mktemp("pred_nocond"), use_condition=False)


@pytest.fixture(scope="module")
def offsets_run(tmp_path_factory) -> tuple[Path, np.ndarray, np.ndarray]:
    """With tip offsets: the graph layers read the press, so every press runs them."""
    return _trained(tmp_path_factory.mktemp("pred_offsets"), offsets="graph")


@pytest.fixture(scope="module")
def head_run(tmp_path_factory) -> tuple[Path, np.ndarray, np.ndarray]:
    """With head offsets: the heads read each point's offsets from the tip, the graph layers
    do not read the press, so a scene's features are cached."""
    return _trained(tmp_path_factory.mktemp("pred_heads"), offsets="heads", offset_width=8)


def test_predict_is_the_network_in_si_units(run) -> None:
    path, points, cond = run
    p = Predictor.load(path)
    deformed, df = p.predict(points, cond)
    model, norm = model_from(load_checkpoint(path / "best.pt"))
    with torch.no_grad():
        disp, f = model(norm.points(torch.from_numpy(points))[None],
                        norm.condition(torch.from_numpy(cond))[None])
    np.testing.assert_allclose(deformed, points + disp[0].numpy() * norm.disp_scale, atol=1e-7)
    assert df == pytest.approx(float(f[0]) * norm.force_scale, rel=1e-5)
    assert p.predict_force(points, cond) == pytest.approx(df, rel=1e-5, abs=1e-7)


def test_refusals(run) -> None:
    path, points, cond = run
    p = Predictor.load(path)
    with pytest.raises(ValueError, match="at least k \\+ 1"):
        p.predict(points[:5], cond)
    bad = points.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        p.predict(bad, cond)
    with pytest.raises(ValueError, match="millimetres"):
        p.predict(points * 1000, cond * 1000)


def test_far_conditions_are_flagged(run) -> None:
    """A press of the training data is inside the envelope (this model, trained one epoch,
    may still predict a force outside the learned range: that alone may be flagged)."""
    path, points, cond = run
    p = Predictor.load(path)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        p.predict(points, cond)
    assert all("change of force" in str(w.message) and "press" not in str(w.message)
               and "extent" not in str(w.message) for w in seen)
    with pytest.warns(UserWarning, match="extrapolates"):
        p.predict(points, cond + np.array([0, 0, 0.2, 0, 0, 0.2], np.float32))
    assert p.extrapolating


def test_duplicate_points_are_allowed(run) -> None:
    path, points, cond = run
    dup = np.concatenate([points, points[:3]])
    deformed, _ = Predictor.load(path).predict(dup, cond)
    np.testing.assert_allclose(deformed[-3:], deformed[:3], atol=1e-6)


@pytest.mark.parametrize("model", ["run", "head_run"])
@pytest.mark.parametrize("n", [26, 1024])
def test_onnx_export_matches_torch(request, tmp_path, model: str, n: int) -> None:
    ort = pytest.importorskip("onnxruntime")
    path, points, cond = request.getfixturevalue(model)
    onnx = tmp_path / "m.onnx"
    res = CliRunner().invoke(cli, ["-q", "export", str(path), "--onnx", str(onnx)])
    assert res.exit_code == 0, res.output
    rng = np.random.default_rng(n)
    pts = np.concatenate([points, rng.uniform(0, 0.1, (max(0, n - len(points)), 3))])[:n]
    pts = pts.astype(np.float32)
    pts[len(points):, 2] = 0
    deformed, df = Predictor.load(path).predict(pts, cond)
    out = ort.InferenceSession(str(onnx)).run(None, {"points": pts[None],
                                                      "condition": cond[None]})
    np.testing.assert_allclose(out[0][0], deformed, atol=1e-5)
    assert float(out[1][0]) == pytest.approx(df, abs=1e-4)


def _bare(path: Path, points: np.ndarray, cond: np.ndarray) -> tuple[np.ndarray, float]:
    """The network as training runs it (its own kNN), in SI units: the reference."""
    model, norm = model_from(load_checkpoint(path / "best.pt"))
    with torch.no_grad():
        disp, f = model(norm.points(torch.from_numpy(points))[None],
                        norm.condition(torch.from_numpy(cond))[None])
    return points + disp[0].numpy() * norm.disp_scale, float(f[0]) * norm.force_scale


def _surface(points: np.ndarray, n: int, seed: int) -> np.ndarray:
    """``points`` padded with random points on their plane to ``n`` (a denser scene)."""
    rng = np.random.default_rng(seed)
    lo, hi = points.min(0), points.max(0)
    extra = rng.uniform(lo, hi, (max(0, n - len(points)), 3))
    extra[:, 2] = np.median(points[:, 2])
    return np.concatenate([points, extra])[:n].astype(np.float32)


@pytest.mark.parametrize("model", ["run", "offsets_run", "nocond_run", "head_run"])
@pytest.mark.parametrize("backend", ["torch", "onnx"])
@pytest.mark.parametrize("n", [26, 1024])
def test_every_backend_gives_the_networks_answer(request, model: str, backend: str, n: int
                                                 ) -> None:
    """Whole network, force alone, and a new press on the same scene (for the paper's
    network and head offsets, from the scene's cached terms) against the network as training
    runs it."""
    if backend == "onnx":
        pytest.importorskip("onnxruntime")
    path, points, cond = request.getfixturevalue(model)
    pts = _surface(points, n, n)
    p = Predictor.load(path, backend=backend)
    deformed, df = p.predict(pts, cond)
    ref, ref_df = _bare(path, pts, cond)
    np.testing.assert_allclose(deformed, ref, atol=1e-5)
    assert df == pytest.approx(ref_df, abs=1e-5)
    assert p.predict_force(pts, cond) == pytest.approx(ref_df, abs=1e-5)
    cond2 = cond + np.array([0, 0, 0, 1e-3, 0, -1e-3], np.float32)   # same scene, new press
    again, df2 = p.predict(pts, cond2)
    ref2, ref_df2 = _bare(path, pts, cond2)
    np.testing.assert_allclose(again, ref2, atol=1e-5)
    assert df2 == pytest.approx(ref_df2, abs=1e-5)
    assert p.predict_force(pts, cond2) == pytest.approx(ref_df2, abs=1e-5)


def test_points_changed_in_place_are_seen(run) -> None:
    path, points, cond = run
    p = Predictor.load(path)
    pts = points.copy()
    p.predict(pts, cond)
    pts[:5] += np.float32(4e-3)               # the caller moves its mesh in place
    np.testing.assert_allclose(p.predict(pts, cond)[0], _bare(path, pts, cond)[0], atol=1e-5)


def test_segment_distance_is_euclidean() -> None:
    from train.inference.region import segment_distance

    start, end = np.array([0.0, 0, 0]), np.array([0.0, 0, -2])
    pts = np.array([[3.0, 4, 0], [0, 0, 5], [1, 0, -1], [0, 0, -6]])
    np.testing.assert_allclose(segment_distance(pts, start, end), [5, 5, 1, 4])
    np.testing.assert_allclose(segment_distance(pts, start, start), [5, 5, np.sqrt(2), 6])


@pytest.mark.parametrize("model", ["run", "offsets_run", "head_run"])
def test_region_covering_the_surface_is_the_whole_model(request, model: str) -> None:
    path, points, cond = request.getfixturevalue(model)
    pts = _surface(points, 300, 3)
    p = Predictor.load(path)
    whole, df = p.predict(pts, cond)
    np.testing.assert_allclose(p.predict(pts, cond, region=10.0)[0], whole, atol=1e-5)
    assert p.predict_force(pts, cond, region=10.0) == pytest.approx(df, abs=1e-5)


def test_region_runs_the_network_on_the_press_and_its_rings(offsets_run) -> None:
    """A model whose layers read the press: the network runs on the points near the tip's
    path and the rings its layers read, and the force pools over them."""
    path, points, cond = offsets_run
    pts = _surface(points, 300, 4)
    radius, k = 0.015, 5
    deformed, df = Predictor.load(path).predict(pts, cond, region=radius)
    # the same region by brute force: distances to the tip's path, hops on a cdist kNN
    a, b = cond[:3].astype(np.float64), cond[3:].astype(np.float64)
    t = np.clip((pts - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
    core = np.linalg.norm(pts - a - t[:, None] * (b - a), axis=1) <= radius
    assert 10 < core.sum() < len(pts) - 50
    knn = np.argsort(((pts[:, None] - pts[None]) ** 2).sum(-1), axis=1)[:, :k]
    used = core.copy()
    for _ in range(3):
        used[knn[used].ravel()] = True
    assert used.sum() > core.sum()
    np.testing.assert_array_equal(deformed[~core], pts[~core])          # left at rest
    order = np.r_[np.flatnonzero(core), np.flatnonzero(used & ~core)]
    ref, ref_df = _bare(path, pts[order], cond)
    np.testing.assert_allclose(deformed[core], ref[: core.sum()], atol=1e-5)
    assert df == pytest.approx(ref_df, abs=1e-5)


@pytest.mark.parametrize("model", ["run", "head_run"])
def test_region_of_a_cached_scene_is_the_whole_model_near_the_press(request, model: str
                                                                     ) -> None:
    """The paper's network or head offsets on a known scene: the whole surface's features
    are cached, so a region moves the points near the tip's path exactly as the whole model
    does, leaves the rest at rest, and its force is the whole surface's."""
    path, points, cond = request.getfixturevalue(model)
    pts = _surface(points, 300, 4)
    pts += np.random.default_rng(0).normal(0, 1e-5, pts.shape).astype(np.float32)  # no ties
    radius = 0.015
    p = Predictor.load(path)
    p.predict(pts, cond + np.array([0, 0, 0, 0, 0, 1e-3], np.float32))   # the scene is known
    deformed, df = p.predict(pts, cond, region=radius)
    a, b = cond[:3].astype(np.float64), cond[3:].astype(np.float64)
    t = np.clip((pts - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
    core = np.linalg.norm(pts - a - t[:, None] * (b - a), axis=1) <= radius
    assert 10 < core.sum() < len(pts) - 50
    ref, ref_df = _bare(path, pts, cond)
    np.testing.assert_allclose(deformed[core], ref[core], atol=1e-5)
    np.testing.assert_array_equal(deformed[~core], pts[~core])
    assert df == pytest.approx(ref_df, abs=1e-5)
    assert p.predict_force(pts, cond, region=radius) == pytest.approx(ref_df, abs=1e-5)


def test_region_must_be_a_positive_radius(run) -> None:
    path, points, cond = run
    with pytest.raises(ValueError, match="positive radius"):
        Predictor.load(path).predict(points, cond, region=0.0)

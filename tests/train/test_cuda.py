"""The GPU path: training (with every augmentation), evaluation and the predictor on CUDA.

CI has no GPU, so these are skipped there with the reason; they run wherever torch sees a CUDA
device. The CPU run of the same options is the reference: the same seeded draws (the epoch's
generator lives on the CPU) and the same arithmetic, so the two agree to float32 rounding.
"""

from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers.cgnn_data import dent_fold

from train.evaluation.references import DISPLACEMENT
from train.evaluation.scoring import evaluate_runs
from train.inference.predictor import Predictor
from train.model.config import CGNNConfig
from train.training.train_params import TrainInputs, TrainOptions, TrainParams
from train.training.train_stage import run_train

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")

SMALL = CGNNConfig(edge_widths=((16, 16),) * 3, disp_widths=(32,), force_widths=(16, 8, 8),
                   offsets="graph")
OPTIONS = TrainOptions(epochs=2, batch=8, lr=3e-3, loss="balanced", rotate=True,
                       point_fraction=0.5, ema=0.9)


@pytest.fixture(scope="module")
def dent(tmp_path_factory) -> tuple[Path, Path]:
    return dent_fold(tmp_path_factory.mktemp("dent"))


def _log(run: Path) -> list[dict]:
    with open(run / "log.csv") as f:
        return list(csv.DictReader(f))


def test_training_on_cuda_follows_the_cpu_run(dent, tmp_path) -> None:
    for device in ("cpu", "cuda"):
        run_train(TrainInputs(*dent), tmp_path / device, TrainParams(OPTIONS, SMALL, device))
    cpu, gpu = _log(tmp_path / "cpu"), _log(tmp_path / "cuda")
    for a, b in zip(cpu, gpu, strict=True):
        for key in ("train_loss", "val_loss", "val_ld_mm"):
            assert float(b[key]) == pytest.approx(float(a[key]), rel=1e-3), key


def test_eval_and_predictor_on_cuda_give_the_cpu_answers(dent, tmp_path) -> None:
    run = tmp_path / "run"
    run_train(TrainInputs(*dent), run, TrainParams(OPTIONS, SMALL, "cpu"))
    on = {d: evaluate_runs([run], device=d).to_json()["runs"][0] for d in ("cpu", "cuda")}
    assert on["cuda"]["metrics"]["all"]["ld_mean_mm"] == pytest.approx(
        on["cpu"]["metrics"]["all"]["ld_mean_mm"], rel=1e-4)
    for name in DISPLACEMENT:
        assert on["cuda"]["references"][name]["ld_mean_mm"] == pytest.approx(
            on["cpu"]["references"][name]["ld_mean_mm"], rel=1e-4)
    g = (np.arange(7) + 0.5) / 7 * 0.1
    points = np.stack([*np.meshgrid(g, g), np.zeros((7, 7))], -1).reshape(-1, 3)
    cond = np.array([0.05, 0.05, 0.0, 0.05, 0.05, -0.002], np.float32)
    want = Predictor.load(run, "cpu", backend="torch").predict(points, cond)
    got = Predictor.load(run, "cuda").predict(points, cond)
    np.testing.assert_allclose(got[0], want[0], atol=1e-6)
    assert got[1] == pytest.approx(want[1], abs=1e-5)
    region = Predictor.load(run, "cuda").predict(points, cond, region=0.02)
    assert region[0].shape == points.shape and np.isfinite(region[0]).all()


@pytest.mark.parametrize("offsets", ["none", "heads"])
def test_a_known_scene_on_cuda_gives_the_cpu_answers(dent, tmp_path, offsets) -> None:
    """The paper's network (and head offsets) keeps a scene's head terms on a first press
    and runs the heads alone after: on CUDA as on the CPU, for a new press and in a region."""
    run = tmp_path / "run"
    run_train(TrainInputs(*dent), run, TrainParams(
        OPTIONS, replace(SMALL, offsets=offsets, offset_width=8), "cpu"))
    g = (np.arange(7) + 0.5) / 7 * 0.1
    points = np.stack([*np.meshgrid(g, g), np.zeros((7, 7))], -1).reshape(-1, 3)
    presses = [np.array([0.05, 0.05, 0.0, 0.05, 0.05, -d], np.float32) for d in (2e-3, 3e-3)]
    cpu = Predictor.load(run, "cpu", backend="torch")
    gpu = Predictor.load(run, "cuda")
    for cond in presses:                     # a new scene, then a press on the known one
        want, got = cpu.predict(points, cond), gpu.predict(points, cond)
        np.testing.assert_allclose(got[0], want[0], atol=1e-6)
        assert got[1] == pytest.approx(want[1], abs=1e-5)
        assert gpu.predict_force(points, cond) == pytest.approx(want[1], abs=1e-5)
    np.testing.assert_allclose(gpu.predict(points, presses[0], region=0.02)[0],
                               cpu.predict(points, presses[0], region=0.02)[0], atol=1e-6)

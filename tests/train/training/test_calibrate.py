"""A run's intervals: the calibration scores are the errors against the data's truth, they are
taken on the fold's validation presses, and a run without them keeps none."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers.cgnn_data import TINY, write_dent_states
from torch import nn

from train.data import load_states
from train.model.normalise import Normaliser
from train.training.calibrate import joined, residuals
from train.training.checkpoint import load_checkpoint
from train.training.train_params import TrainInputs, TrainOptions, TrainParams
from train.training.train_stage import run_train


class Still(nn.Module):
    """A model that moves nothing and predicts no change of force."""

    def forward(self, points: torch.Tensor, cond: torch.Tensor, *_: object
                ) -> tuple[torch.Tensor, torch.Tensor]:
        return torch.zeros_like(points), torch.zeros(len(points))


def test_scores_are_the_errors_against_the_truth(tmp_path: Path) -> None:
    """With nothing moving, a point's score is how far the dent truly moved it, the force's
    the true change, and the features the press's geometry (a vertical press)."""
    arrays = write_dent_states(tmp_path / "s.h5")
    states = load_states(tmp_path / "s.h5")
    pairs = states.pairs["multi"]
    norm = Normaliser((0.05, 0.05, 0.0), 0.05, 1e-3, 1.0, 0.1)
    r = residuals(Still(), norm, states, pairs, batch=7)
    s, e = pairs[:, 0].numpy(), pairs[:, 1].numpy()
    pts, tip = arrays["states/points"].astype(np.float64), arrays["states/tip"]
    moved = np.linalg.norm(pts[e] - pts[s], axis=-1)                      # (E, N)
    np.testing.assert_allclose(r.point_error, moved.ravel(), atol=1e-6)
    np.testing.assert_allclose(r.force_error, -(arrays["states/force"][e]
                                                - arrays["states/force"][s]), atol=1e-5)
    top, bottom = tip[s, 2:3], tip[e, 2:3]                                # the press, in z
    z = pts[s, :, 2]
    out_of_range = np.maximum(z - top, 0) + np.maximum(bottom - z, 0)
    planar = np.linalg.norm(pts[s, :, :2] - tip[s, None, :2], axis=-1)
    np.testing.assert_allclose(r.point_features[:, 0], np.hypot(planar, out_of_range).ravel(),
                               atol=1e-6)
    np.testing.assert_allclose(r.force_features[:, 0], top[:, 0] - bottom[:, 0], atol=1e-6)


def test_residuals_keep_each_examples_points_when_cut_and_joined(tmp_path: Path) -> None:
    """Batches of 7 number the examples on; a subset and a join renumber them, each
    example's points and force staying together."""
    arrays = write_dent_states(tmp_path / "s.h5")
    states = load_states(tmp_path / "s.h5")
    pairs = states.pairs["multi"]
    r = residuals(Still(), Normaliser((0.05, 0.05, 0.0), 0.05, 1e-3, 1.0, 0.1), states, pairs,
                  batch=7)
    n = arrays["states/points"].shape[1]
    np.testing.assert_array_equal(r.point_example, np.repeat(np.arange(len(pairs)), n))
    keep = np.arange(len(pairs)) % 3 == 0
    both = joined([r.subset(keep), r.subset(~keep)])
    order = np.r_[np.flatnonzero(keep), np.flatnonzero(~keep)]
    np.testing.assert_array_equal(both.point_example, r.point_example)
    np.testing.assert_array_equal(both.force_error, r.force_error[order])
    np.testing.assert_array_equal(both.point_error,
                                  r.point_error.reshape(len(pairs), n)[order].ravel())


@pytest.fixture(scope="module")
def trained(dent: tuple[Path, Path], tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("cal") / "run"
    run_train(TrainInputs(*dent), out, TrainParams(TrainOptions(epochs=1, batch=8), TINY, "cpu"))
    return out


def test_a_run_keeps_intervals_calibrated_on_its_validation_presses(dent, trained) -> None:
    _, splits = dent
    val = json.loads(splits.read_text())["folds"][0]["val"]
    table = load_checkpoint(trained / "best.pt")["intervals"]
    assert table["presses"] == len(val["groups"]) > 0
    assert table["examples"] == len(val["single"]) + len(val["multi"])
    radius = np.array(table["points"]["width"], dtype=float)
    assert (np.diff(radius, axis=-1)[np.isfinite(radius[..., 1:])] >= 0).all()  # by level
    assert "intervals" not in load_checkpoint(trained / "last.pt")


def test_a_run_without_validation_keeps_none(dent, tmp_path: Path) -> None:
    run_train(TrainInputs(*dent), tmp_path / "run",
              TrainParams(TrainOptions(epochs=1, batch=8, no_val=True), TINY, "cpu"))
    assert "intervals" not in load_checkpoint(tmp_path / "run" / "best.pt")

"""Rigid motions of batches (rotation augmentation, robustness tests) against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from helpers.cgnn_data import dent, dent_fold, write_dent_states

from train.data import load_states, make_batch
from train.model.config import CGNNConfig
from train.training.augment import about_normal, move_batch, tilt
from train.training.train_params import TrainInputs, TrainOptions, TrainParams
from train.training.train_stage import run_train

SMALL = CGNNConfig(edge_widths=((16, 16),) * 3, disp_widths=(32,), force_widths=(16, 8, 8))
CENTRE = torch.tensor([0.05, 0.05, 0.0])


def test_a_quarter_turn_of_a_dent_is_the_dent_of_the_turned_tip(tmp_path) -> None:
    """The dent is symmetric about its tip, so the turned example is the closed-form dent of
    the turned surface under the turned tip; the force change is unchanged."""
    write_dent_states(tmp_path / "s.h5")
    states = load_states(tmp_path / "s.h5")
    b = make_batch(states, states.pairs["single"][:6])
    t = move_batch(b, about_normal(torch.full((6,), math.pi / 2)), CENTRE)
    for i in range(6):
        rest, tip = t.points[i].numpy(), t.cond[i, 3:].numpy()
        flat = rest.copy()
        flat[:, 2] = 0.0                                  # the turned rest grid, undented
        start_depth = -float(t.cond[i, 2])
        expect = dent(flat, tip[:2], -float(tip[2]))
        np.testing.assert_allclose(t.target[i].numpy(), expect, atol=1e-7)
        np.testing.assert_allclose(rest, dent(flat, tip[:2], start_depth), atol=1e-7)
    assert torch.equal(t.dforce, b.dforce) and torch.equal(t.mask, b.mask)


def test_turns_and_tilts_are_rotations() -> None:
    for r in (about_normal(torch.rand(5) * 6.3), tilt(30.0, 5)):
        eye = torch.eye(3).expand(5, 3, 3)
        torch.testing.assert_close(r @ r.transpose(1, 2), eye, atol=1e-6, rtol=0)
        torch.testing.assert_close(torch.linalg.det(r), torch.ones(5), atol=1e-6, rtol=0)
    z = torch.tensor([0.0, 0.0, 1.0])
    torch.testing.assert_close(about_normal(torch.tensor([1.0]))[0] @ z, z)
    assert float(tilt(90.0, 1)[0] @ z @ torch.tensor([0.0, -1.0, 0.0])) == pytest.approx(1.0)


def test_rotation_augmented_training_is_seeded_and_differs(tmp_path) -> None:
    data, splits = dent_fold(tmp_path)
    runs = {}
    for name, rotate, force in (("a", True, True), ("b", True, True), ("plain", False, True),
                                ("still", True, False)):
        opts = TrainOptions(epochs=2, batch=8, lr=3e-3, rotate=rotate, rotate_force=force)
        best = run_train(TrainInputs(data, splits), tmp_path / name,
                         TrainParams(opts, SMALL, "cpu")).best
        runs[name] = torch.load(best, weights_only=True)["model"]
    key = next(iter(runs["a"]))
    assert torch.equal(runs["a"][key], runs["b"][key])
    assert not torch.equal(runs["a"][key], runs["plain"][key])
    assert not torch.equal(runs["a"][key], runs["still"][key])   # half unturned, force apart

"""The no-learning references against the closed-form dent (tests/helpers/cgnn_data.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner
from helpers.cgnn_data import SIGMA, write_dent_split, write_dent_states

from data_schema.metrics_doc import FORCE_LINEAR, NEAREST_PRESS, NOTHING_MOVES
from pipeline.cli import cli
from train.data import Batch, example_pairs, load_states, make_batch, role_examples
from train.evaluation.references import References, with_tip
from train.model.config import CGNNConfig
from train.training.train_params import TrainInputs, TrainOptions, TrainParams
from train.training.train_stage import run_train

SMALL = CGNNConfig(edge_widths=((8, 8),) * 3, disp_widths=(8,), force_widths=(8, 8, 8))


@pytest.fixture(scope="module")
def dent(tmp_path_factory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("refs")
    data = d / "states.h5"
    write_dent_states(data, places=4, repeats=2, steps=5)
    splits = d / "splits.json"
    write_dent_split(data, splits, (4, 2, 2))
    return data, splits


def _fold(dent) -> tuple:
    data, splits = dent
    doc = json.loads(Path(splits).read_text())
    states = load_states(data)
    train = example_pairs(states, role_examples(doc, 0, "train"))
    test = example_pairs(states, role_examples(doc, 0, "test"))
    return states, train, test


def test_nothing_moves_costs_the_true_displacement(dent):
    states, train, test = _fold(dent)
    b = make_batch(states, test)
    p = References(states, train).predict(NOTHING_MOVES, b)
    depth = (b.cond[:, 2] - b.cond[:, 5]).numpy()                  # how much deeper, m
    r2 = ((b.points[..., :2] - b.cond[:, None, :2]) ** 2).sum(-1).numpy()
    truth = depth[:, None] * np.exp(-r2 / (2 * SIGMA**2))        # every point's sinking
    got = torch.linalg.vector_norm(p.deformed - b.target, dim=-1).numpy()
    np.testing.assert_allclose(got, truth, atol=2e-7)
    assert (p.dforce == 0).all()


def test_nearest_press_repeats_an_identical_press_exactly(dent):
    """Every place is pressed twice alike (sequences s and s + 4): trained on the first
    presses, the nearest press predicts the second presses' single steps exactly."""
    states = load_states(dent[0])
    single = states.pairs["single"]
    first = single[single[:, 0] < 4 * 6]                  # sequences 0..3 (6 states each)
    b = make_batch(states, single[single[:, 0] >= 4 * 6])
    p = References(states, first).predict(NEAREST_PRESS, b)
    assert torch.linalg.vector_norm(p.deformed - b.target, dim=-1).max() < 1e-7
    assert (p.dforce - b.dforce).abs().max() < 1e-6


def test_linear_force_is_exact_where_force_is_linear_in_the_tip_motion(dent):
    """The dent's force is 0.5 N per mm of depth: dF = 500 N/m x (tip motion down)."""
    states, train, test = _fold(dent)
    refs = References(states, train)
    np.testing.assert_allclose(refs.coef.numpy(), [0, 0, -500.0, 0], atol=1e-3)
    b = make_batch(states, test)
    p = refs.predict(FORCE_LINEAR, b)
    assert (p.dforce - b.dforce).abs().max() < 1e-4 and torch.isnan(p.deformed).all()


def test_the_tip_point_goes_to_the_end_of_c():
    points = torch.tensor([[[0.0, 0.0, 0.0], [0.05, 0.05, -0.001]]])      # a marker, the tip
    cond = torch.tensor([[0.05, 0.05, -0.001, 0.051, 0.05, -0.02]])
    b = Batch(points, points.clone(), torch.ones(1, 2, dtype=torch.bool), cond,
              torch.zeros(1))
    moved = with_tip(b, b.points)
    assert torch.equal(moved[0, 0], points[0, 0])
    assert torch.allclose(moved[0, 1], cond[0, 3:])


def test_eval_reports_the_references_and_strict_fails_a_model_that_does_not_beat_them(
        dent, tmp_path):
    """A 1-epoch model cannot beat a lookup that is exact for half the test examples."""
    run = tmp_path / "run"
    run_train(TrainInputs(*dent), run, TrainParams(TrainOptions(epochs=1, batch=8), SMALL, "cpu"))
    out = tmp_path / "metrics.json"
    res = CliRunner().invoke(cli, ["-q", "eval", str(run), "--out", str(out), "--no-rrd",
                                   "--strict"])
    assert res.exit_code == 1, res.output
    assert "does not beat 'nearest press'" in res.output
    row = json.loads(out.read_text())["overall"][0]
    assert set(row["references"]) == {"nothing moves", "nearest press", "force, linear"}
    assert row["references"]["force, linear"]["ld_mean_mm"] is None
    assert row["gain"]["ld_reference"] == "nearest press" and row["gain"]["ld_gain"] < 0
    table = out.with_suffix(".md").read_text()
    assert "*reference: nothing moves*" in table and "Mean L_d per fold" not in table

"""Named training recipes (``pipeline train --recipe``): the paper's settings stated once, and
ours by name; options given on the command line override a recipe's values."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

import train.paper as paper
import train.training.train_stage
from pipeline.cli import cli
from train.model.config import OFFSET_WIDTH, CGNNConfig
from train.training.recipes import OURS, PAPER, recipe
from train.training.train_params import TrainOptions

OURS_FLAGS = ("--offsets", "heads", "--loss", "balanced", "--rotate", "--ema", "0.99", "--lr",
              "2e-3")


@pytest.fixture
def resolved(monkeypatch, tmp_path):
    """``pipeline train ARGS`` up to the runner: the TrainParams it would run."""
    for name in ("states.h5", "splits.json"):
        (tmp_path / name).touch()
    seen = []

    def fake_run_train(inputs, out, params, rrd=None):
        seen.append(params)
        raise SystemExit(0)

    monkeypatch.setattr(train.training.train_stage, "run_train", fake_run_train)

    def run(*args: str) -> train.training.train_params.TrainParams:
        seen.clear()
        res = CliRunner().invoke(cli, ["train", "--data", str(tmp_path / "states.h5"),
                                       "--splits", str(tmp_path / "splits.json"), "--out",
                                       str(tmp_path / "run"), *args])
        assert seen, res.output
        return seen[0]
    return run


def test_the_paper_recipe_is_the_papers_settings() -> None:
    opts, config = PAPER.settings()
    assert (opts.epochs, opts.batch, opts.lr, opts.alpha, config.k) == \
        (250, 32, 1e-4, 88.0, 5) == (paper.EPOCHS, paper.BATCH, paper.LR, paper.ALPHA, paper.K)
    assert (opts, config) == (TrainOptions(), CGNNConfig())


def test_plain_train_runs_the_paper_recipe(resolved) -> None:
    assert resolved() == resolved("--recipe", "paper")
    params = resolved()
    assert (params.options, params.config) == PAPER.settings()


def test_recipe_ours_is_the_explicit_flags(resolved) -> None:
    ours = resolved("--recipe", "ours")
    spelt = resolved(*OURS_FLAGS)
    assert (ours.options, ours.config, ours.device) == (spelt.options, spelt.config, spelt.device)
    assert (ours.recipe, spelt.recipe) == ("ours", "paper")       # the name, for provenance
    assert (ours.options, ours.config) == OURS.settings()
    assert ours.config.offsets == "heads" and ours.config.offset_width == OFFSET_WIDTH
    assert ours.options.rotate and ours.options.ema == 0.99
    assert (ours.options.loss, ours.options.lr) == ("balanced", 2e-3)
    assert OURS.flags() == ("--offsets", "heads", "--loss", "balanced", "--rotate", "--ema",
                            "0.99", "--lr", "0.002")


def test_a_flag_given_overrides_the_recipe(resolved) -> None:
    ours = resolved("--recipe", "ours")
    mine = resolved("--recipe", "ours", "--lr", "1e-3", "--offsets", "none", "--epochs", "7")
    assert (mine.options.lr, mine.config.offsets, mine.options.epochs) == (1e-3, "none", 7)
    assert mine.options == TrainOptions(**{**vars(ours.options), "lr": 1e-3, "epochs": 7})
    # a value given equal to the paper's default still overrides the recipe's
    assert resolved("--recipe", "ours", "--lr", "1e-4").options.lr == 1e-4
    assert not resolved("--recipe", "ours", "--no-rotate").options.rotate
    assert resolved("--recipe", "ours", "--no-ema").options.ema is None
    assert resolved("--recipe", "ours", "--loss", "paper").options.loss == "paper"


def test_the_demo_trains_with_recipe_ours(resolved, tmp_path) -> None:
    from pipeline.demo_plan import NETWORKS, QUICK, RECIPE, Pretraining, demo_steps

    networks = {"head-offsets": {"offsets": "heads"}, "tip-offsets": {"offsets": "graph"},
                "paper": {"offsets": "none"}}
    for flags, network in ((RECIPE, {}), *((NETWORKS[n], networks[n]) for n in NETWORKS)):
        trains = [s for s in demo_steps(tmp_path / "demo", 0, QUICK, "cpu", flags,
                                        pretraining=Pretraining.GENERIC)
                  if s.args[0] == "train"]
        assert {s.stage for s in trains} == {"train (pre-training)", "train (fine-tuning)"}
        for step in trains:
            epochs, lr = (QUICK.generic.epochs, QUICK.generic.lr) \
                if step.stage == "train (pre-training)" else (QUICK.finetune_epochs, QUICK.lr)
            args = [a for a in step.args[step.args.index("--epochs"):] if a != "--init"]
            got = resolved(*(a for a in args if not a.endswith(".pt")))
            want = OURS.settings(epochs=epochs, lr=lr, batch=QUICK.batch, **network)
            assert (got.options, got.config, got.device) == (*want, "cpu")


def test_tip_offsets_without_the_condition_is_refused(resolved, tmp_path) -> None:
    res = CliRunner().invoke(cli, ["train", "--data", str(tmp_path / "states.h5"), "--splits",
                                   str(tmp_path / "splits.json"), "--out", str(tmp_path / "r"),
                                   "--recipe", "ours", "--no-cond"])
    assert res.exit_code == 2 and "add --offsets none" in res.output
    assert resolved("--recipe", "ours", "--no-cond", "--offsets", "none").config.use_condition \
        is False


@pytest.mark.parametrize(("flags", "words"), [
    (("--offsets", "heads", "--no-cond"), "which noCond removes"),
    (("--offsets", "graph", "--no-cond"), "which noCond removes"),
    (("--offsets", "tip"), "--offsets 'tip': must be one of none, graph, heads"),
    (("--offsets", "heads", "--offset-width", "0"), "--offset-width 0: must be >= 1"),
    (("--ema", "0.9", "--no-ema"), "--ema and --no-ema"),
])
def test_offsets_without_the_condition_are_refused(resolved, tmp_path, flags, words) -> None:
    res = CliRunner().invoke(cli, ["train", "--data", str(tmp_path / "states.h5"), "--splits",
                                   str(tmp_path / "splits.json"), "--out", str(tmp_path / "r"),
                                   "--recipe", "paper", *flags])
    assert res.exit_code == 2 and words in res.output


def test_an_unknown_recipe_is_bad_input() -> None:
    from core.errors import BadInput

    with pytest.raises(BadInput, match="not one of paper, ours"):
        recipe("fast")
    with pytest.raises(TypeError, match="not a training setting"):
        OURS.settings(learning_rate=1.0)


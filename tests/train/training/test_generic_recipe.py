"""The shipped generic model's recipe is a record of its own: it is what the shipped file says
it was made by, the build runs it, and the demo's own settings reach neither it nor the
decision to rebuild."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from pipeline import demo_plan, generic_build
from pipeline.demo_plan import NETWORKS, QUICK, RECIPE_NETWORK, Pretraining, demo_steps
from pipeline.generic_build import build_steps, changes
from train.generic_model import SHIPPED
from train.model.config import CGNNConfig
from train.training.checkpoint import load_checkpoint
from train.training.generic_recipe import SHIPPED_RECIPE
from train.training.recipes import RECIPES
from train.training.train_params import TrainOptions

WORK = Path("work")


@pytest.fixture(scope="module")
def shipped() -> dict:
    return load_checkpoint(SHIPPED)


def _value(command: list[str], flag: str) -> str:
    return command[command.index(flag) + 1]


def test_the_recipe_is_what_the_shipped_file_says_it_was_made_by(shipped) -> None:
    """The counts and the seed its commands name, and the options and network its run kept
    (the run's own record, not the commands), are the recipe's."""
    r = SHIPPED_RECIPE
    simulate, split, train = shipped["provenance"]["steps"]
    assert simulate[:3] == ["pipeline", "simulate", "--prior"] and train[1] == "train"
    assert (int(_value(simulate, "--prior")), int(_value(simulate, "--locations")),
            int(_value(simulate, "--directions"))) == (r.phantoms, r.locations, r.directions)
    assert {int(_value(step, "--seed")) for step in (simulate, split, train)} == {r.seed}
    assert _value(split, "--folds") == "1" and _value(train, "--recipe") == r.recipe
    options, config = RECIPES[r.recipe].settings(epochs=r.epochs, lr=r.lr, batch=r.batch,
                                                 seed=r.seed)
    assert TrainOptions(**shipped["meta"]["options"]) == options
    assert CGNNConfig.from_dict(shipped["config"]) == config
    assert (options.epochs, options.lr, options.batch) == (120, 5e-4, 32)


def test_the_demos_name_for_the_shipped_network_is_the_shipped_files() -> None:
    """The demo refuses another network than the shipped model's (``--network``): the one it
    names so is the network the file holds."""
    flags = NETWORKS[RECIPE_NETWORK]
    network = CGNNConfig.from_dict(load_checkpoint(SHIPPED)["config"])
    assert _value(list(flags), "--offsets") == network.offsets.value


def test_the_quick_demos_generic_model_is_the_builds() -> None:
    """``demo --quick --pretraining generic`` runs the build's commands (on the CPU)."""
    demo = [s.args for s in demo_steps(WORK, 5, QUICK, "cpu", pretraining=Pretraining.GENERIC)
            if s.outputs[0].parent.name in ("msm", "generic")]
    assert demo == [s.args for s in build_steps(WORK)]


def test_a_demo_setting_changes_neither_the_build_nor_the_rebuild_decision(shipped,
                                                                            monkeypatch) -> None:
    """The quick settings (its fine-tuning, its batch, even its generic model) and the
    demo's training flags changed: the build runs the same commands and the shipped file is
    still current; the demo's own plan does change."""
    before = [s.args for s in build_steps(WORK)]
    other = replace(QUICK, lr=1e-2, batch=8, finetune_epochs=3, pretrain_epochs=2,
                    generic=replace(QUICK.generic, epochs=1, phantoms=3))
    for module in (demo_plan, generic_build):
        monkeypatch.setattr(module, "QUICK", other, raising=False)
    monkeypatch.setattr(demo_plan, "RECIPE", ("--recipe", "paper"))
    assert [s.args for s in build_steps(WORK)] == before
    assert changes(shipped["provenance"]) == []
    demo = demo_steps(WORK, 0, other, "cpu", pretraining=Pretraining.GENERIC)
    assert [s.args for s in demo if s.stage == "train (pre-training)"] != before[-1:]


@pytest.mark.parametrize(("part", "edit"), [
    ("steps", lambda r: {**r, "steps": [*r["steps"][:2],
                                        [a.replace("120", "121") for a in r["steps"][2]]]}),
    ("prior", lambda r: {**r, "prior": {**r["prior"], "k_fixed": [4.0, 22.0]}}),
    ("built_by", lambda r: {**r, "built_by": "by hand"}),
])
def test_a_record_another_build_would_not_write_asks_for_a_rebuild(shipped, part,
                                                                     edit) -> None:
    """A record whose epochs, prior range or command differ from today's is named stale
    by that part alone; the torch build it was made with is not a reason."""
    record = shipped["provenance"]
    assert changes(edit(record)) == [part]
    assert changes({**record, "torch": "0.0"}) == []

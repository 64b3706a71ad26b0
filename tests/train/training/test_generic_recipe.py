"""The shipped generic model's recipe is a record of its own: it is what the shipped file says
it was made by, the build runs it, and the demo's own settings reach neither it nor the
decision to rebuild."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from pipeline import demo_plan
from pipeline.demo_plan import (
    NETWORKS,
    QUICK,
    RECIPE,
    RECIPE_NETWORK,
    Pretraining,
    Settings,
    Step,
    demo_steps,
)
from pipeline.generic_build import build_steps, changes
from train.generic_model import SHIPPED, SHIPPED_CURVED
from train.model.config import CGNNConfig, Offsets
from train.training.checkpoint import load_checkpoint
from train.training.generic_recipe import CURVED_RECIPE, SHIPPED_RECIPE
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


# The demo's own quick settings, every one changed (its generic model's recipe kept): its
# fine-tuning's epochs, step size and batch, its per-fold pre-training and MSM set, its study
DEMOS_OWN = replace(QUICK, lr=1e-2, batch=8, finetune_epochs=3, pretrain_epochs=2,
                    msm_locations=4, msm_directions=1, fit_sequences=2, scarcity_epochs=1,
                    scarcity_groups=2, solid_epochs=1)


def _plan(s: Settings, recipe: tuple[str, ...] = RECIPE) -> list[Step]:
    return demo_steps(WORK, 5, s, "cpu", recipe, pretraining=Pretraining.GENERIC)


def _generic(plan: list[Step]) -> list[tuple[str, ...]]:
    """The commands of the plan's generic model (msm/prior*, runs/generic)."""
    return [s.args for s in plan if s.outputs[0].parent.name in ("msm", "generic")]


def _tuning(plan: list[Step]) -> list[list[str]]:
    """The commands of the plan's fine-tuning runs."""
    return [list(s.args) for s in plan if s.stage == "train (fine-tuning)"]


def test_the_quick_demos_generic_model_is_the_builds() -> None:
    """``demo --quick --pretraining generic`` runs the build's commands (on the CPU)."""
    assert _generic(_plan(QUICK)) == [s.args for s in build_steps(WORK)]


def test_the_demos_own_settings_do_not_reach_its_generic_model() -> None:
    """The quick settings' own knobs changed: the demo's generic model is still made by the
    build's commands, while its fine-tuning takes the new epochs, step size and batch (so a
    generic model that read them would differ)."""
    assert DEMOS_OWN.generic == QUICK.generic
    plan = _plan(DEMOS_OWN)
    assert _generic(plan) == [s.args for s in build_steps(WORK)]
    tuning = _tuning(plan)
    assert len(tuning) == 2 * QUICK.folds and tuning != _tuning(_plan(QUICK))
    for args in tuning:
        assert (_value(args, "--epochs"), _value(args, "--lr"), _value(args, "--batch")) == \
            ("3", "0.01", "8")


def test_the_demos_flags_change_neither_the_build_nor_the_rebuild_decision(shipped,
                                                                            monkeypatch) -> None:
    """The demo's quick settings and training flags replaced where the demo reads them
    (``demo_plan.QUICK``, ``demo_plan.RECIPE``): the build runs the same commands and the
    shipped file is still current, while the demo's own runs do take the new flags."""
    before = [s.args for s in build_steps(WORK)]
    flags = NETWORKS["paper"]
    assert flags != RECIPE
    monkeypatch.setattr(demo_plan, "QUICK", DEMOS_OWN)
    monkeypatch.setattr(demo_plan, "RECIPE", flags)
    assert [s.args for s in build_steps(WORK)] == before
    assert changes(shipped["provenance"]) == []
    tuning = _tuning(_plan(demo_plan.QUICK, demo_plan.RECIPE))
    assert tuning and all(_value(args, "--offsets") == Offsets.NONE.value for args in tuning)


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


def test_the_curved_model_starts_from_the_shipped_one_and_is_rebuilt_with_it() -> None:
    """The model for curved labs records the shipped model's weights it was pre-trained from
    (``--init generic``, the moulds' prior): another shipped model asks for its rebuild."""
    record = load_checkpoint(SHIPPED_CURVED)["provenance"]
    assert record["start"] == load_checkpoint(SHIPPED)["provenance"]["weights_sha256"]
    simulate, _, train = record["steps"]
    assert "--moulds" in simulate and _value(train, "--init") == CURVED_RECIPE.start
    assert changes(record, CURVED_RECIPE) == []
    assert changes({**record, "start": "0" * 64}, CURVED_RECIPE) == ["start"]

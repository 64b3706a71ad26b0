"""A run's settings the code branches on are enums from the command line to the loop, and
plain text on disk: a checkpoint's options and network (its own, or one written before the
enums, or before a field existed) read back as members; the settings refuse, as they are made,
what the command line refuses (every bound: ``tests/pipeline/test_cli_refusals.py``)."""

from __future__ import annotations

import json

import pytest

from core.errors import BadInput
from train.model.config import CGNNConfig, Offsets
from train.training.migrate import migrate
from train.training.recipes import OURS
from train.training.train_params import Loss, Schedule, TrainOptions, TrainParams


def test_options_are_plain_text_on_disk_and_members_in_the_code() -> None:
    opts = TrainOptions(loss=Loss.BALANCED, schedule=Schedule.COSINE)
    plain = opts.to_dict()
    assert (plain["loss"], plain["schedule"]) == ("balanced", "cosine")
    assert type(plain["loss"]) is str and type(plain["schedule"]) is str
    assert json.loads(json.dumps(plain)) == plain
    back = TrainOptions.from_dict(plain)
    assert back == opts and back.loss is Loss.BALANCED and back.schedule is Schedule.COSINE


def test_a_checkpoint_s_text_from_before_the_enums_reads_as_members() -> None:
    """The meta of a run written when the options were strings, and before ``schedule`` and
    ``ema`` existed: migrated, then read, they are the members (and today's defaults)."""
    old = {"meta": {"config": {k: v for k, v in CGNNConfig().to_dict().items()
                               if k not in ("offsets", "offset_width")} | {"tip_offsets": True},
                    "options": {"fold": 1, "epochs": 3, "loss": "balanced"},
                    "variant": {"model": "cGNN", "train_data": "Exp", "rotate": False,
                                "aug": False, "pretrained": None}}}
    meta = migrate(old)["meta"]
    opts = TrainOptions.from_dict(meta["options"])
    assert opts.loss is Loss.BALANCED and opts.schedule is Schedule.CONSTANT
    assert (opts.fold, opts.epochs, opts.ema) == (1, 3, None)
    config = CGNNConfig.from_dict(meta["config"])
    assert config.offsets is Offsets.GRAPH
    assert CGNNConfig(**meta["config"]) == config         # lists, as on disk, compare alike


def test_the_recipe_gives_members() -> None:
    opts, config = OURS.settings()
    assert opts.loss is Loss.BALANCED and config.offsets is Offsets.HEADS


@pytest.mark.parametrize(("make", "words"), [
    (lambda: TrainOptions(schedule="linear"), "schedule 'linear': must be one of constant, "
                                              "cosine"),
    (lambda: TrainOptions(no_val=True, patience=3), "patience counts epochs without a "
                                                    "better validation loss: not with no_val"),
    (lambda: TrainOptions(rotate_force=False), "--no-rotate-force leaves the force's "
                                               "examples unturned by the rotation: it needs "
                                               "--rotate"),
    (lambda: TrainOptions(epochs=0), "epochs 0: must be >= 1"),
    (lambda: TrainOptions(batch=2.5), "batch 2.5: not a whole number"),
    (lambda: CGNNConfig(k=1), "k 1: must be >= 2"),
    (lambda: CGNNConfig(offsets="tip"), "offsets 'tip': must be one of none, graph, heads"),
    (lambda: TrainParams(device="tpu"), "device 'tpu': must be one of auto, cpu, cuda"),
])
def test_the_settings_refuse_what_the_command_line_refuses(make, words) -> None:
    with pytest.raises(BadInput) as e:
        make()
    assert str(e.value) == words or str(e.value).startswith(words)

"""The generic model shipped with the package: small, made by today's recipe, read by
``train --init generic``, and already better than "nothing moves" on a lab it never saw."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest
import torch
from click.testing import CliRunner
from helpers.staged_twin import staged_twin

from data_schema.metrics_doc import NOTHING_MOVES
from live.session.model import LiveModel
from pipeline.cli import cli
from pipeline.generic_build import changes
from pipeline.options import Checkpoint
from train.evaluation.run_errors import example_errors, on_lab, reference_errors
from train.generic_model import NAME, SHIPPED, resolve, slim, to_bytes, weights_sha256
from train.training.checkpoint import load_checkpoint


@pytest.fixture(scope="module")
def shipped() -> dict:
    return load_checkpoint(SHIPPED)


@pytest.fixture(scope="module")
def lab(tmp_path_factory) -> Path:
    """A twin lab (2 places x 2 presses) and a 2-fold manifest of it."""
    folder = staged_twin(tmp_path_factory.mktemp("lab"))
    res = CliRunner().invoke(cli, ["-q", "split", str(folder / "states.h5"), "--out",
                                   str(folder / "splits.json"), "--folds", "2", "--no-rrd"])
    assert res.exit_code == 0, res.output
    return folder


def test_the_shipped_model_is_small_and_made_by_todays_recipe(shipped):
    """Under 2 MB; its record is the build today's code would run (the prior's ranges, the
    steps), so a change to either fails here until `python scripts/build_generic.py` is run;
    its weights are the ones the record names."""
    assert SHIPPED.stat().st_size <= 2e6
    record = shipped["provenance"]
    assert changes(record) == [], "changed since the shipped file: rebuild the generic model"
    assert record["weights_sha256"] == weights_sha256(shipped)
    assert "optimizer" not in shipped and "trained" not in shipped
    assert shipped["intervals"] is not None          # live and eval read its intervals


def test_slimming_writes_the_same_bytes_twice_and_reads_back(shipped, tmp_path):
    """The file's bytes depend on its content only: not on the name it is saved under, nor
    on whether the run held its network's config once or twice (two builds of the same
    model differed so, before :func:`canonical`); what is written reads back as a
    checkpoint with the same weights."""
    shared = {**shipped, "meta": {**shipped["meta"], "config": shipped["config"]}}
    apart = {**shipped, "meta": {**shipped["meta"], "config": copy.deepcopy(shipped["config"])}}
    first = to_bytes(slim(shared, {"built_by": "a test"}))
    assert first == to_bytes(slim(apart, {"built_by": "a test"}))
    (tmp_path / "g.pt").write_bytes(first)
    back = load_checkpoint(tmp_path / "g.pt")
    assert weights_sha256(back) == weights_sha256(shipped)
    assert back["meta"]["data"]["file"] == Path(shipped["meta"]["data"]["file"]).name


def test_init_and_live_name_the_shipped_model():
    """``--init generic`` and ``live --model generic`` resolve to the shipped file; live takes
    it on any phantom's markers (it was trained on none in particular)."""
    assert resolve(NAME) == SHIPPED and resolve("runs/x/best.pt") == Path("runs/x/best.pt")
    assert Checkpoint(folder=True).convert(NAME, None, None) == SHIPPED
    live = LiveModel(SHIPPED, [f"m{i}" for i in range(20)])
    assert live.predictor.point_names is None


def test_with_no_lab_data_it_beats_nothing_moves(shipped, lab):
    """Zero-shot on a twin lab it never saw: its mean L_d on each fold's test presses is
    below "nothing moves" on the same examples (the lab's own measured states as truth)."""
    for fold in range(2):
        run = on_lab(shipped, lab / "states.h5", lab / "splits.json", fold)
        errs, _ = example_errors(run)
        still = reference_errors(run)[NOTHING_MOVES]
        assert errs.ld_mean.mean() < still.ld_mean.mean(), fold


def test_train_init_generic_fine_tunes_from_the_shipped_model(lab, tmp_path):
    res = CliRunner().invoke(cli, ["-q", "train", "--data", str(lab / "states.h5"), "--splits",
                                   str(lab / "splits.json"), "--out", str(tmp_path / "run"),
                                   "--epochs", "1", "--init", NAME, "--recipe", "ours",
                                   "--device", "cpu", "--no-rrd"])
    assert res.exit_code == 0, res.output + res.stderr
    meta = torch.load(tmp_path / "run" / "best.pt", weights_only=True)["meta"]
    assert Path(meta["init"]) == SHIPPED.resolve()


def test_init_refuses_a_missing_file_in_one_line(lab, tmp_path):
    res = CliRunner().invoke(cli, ["-q", "train", "--data", str(lab / "states.h5"), "--splits",
                                   str(lab / "splits.json"), "--out", str(tmp_path / "run"),
                                   "--init", str(tmp_path / "nope.pt")])
    assert res.exit_code == 2 and "nope.pt" in res.output + res.stderr

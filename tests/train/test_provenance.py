"""The provenance of what train, eval and export write: the checkpoints (and provenance.json
beside log.csv), metrics.json, the ONNX model's metadata."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import onnx
import pytest
from click.testing import CliRunner
from helpers.cgnn_data import dent_fold

from core.provenance import sha256_file
from data_schema.metrics_doc import METRICS, validate_metrics
from pipeline.cli import cli
from train.training.checkpoint import load_checkpoint
from train.training.run_files import LOG_FIELDS

TINY = ("--epochs", "2", "--batch", "8", "--lr", "3e-3", "--device", "cpu", "--no-rrd")


@pytest.fixture(scope="module")
def made(tmp_path_factory) -> Path:
    """A dent's states and manifest, a pre-trained run, a run fine-tuned from it, their
    metrics and the fine-tuned model's ONNX."""
    d = tmp_path_factory.mktemp("prov")
    data, splits = dent_fold(d)
    common = ("--data", str(data), "--splits", str(splits), "--recipe", "ours", *TINY)
    for args in (("train", *common, "--out", str(d / "pre")),
                 ("train", *common, "--out", str(d / "tl"), "--init", str(d / "pre" / "best.pt"),
                  "--epochs", "1"),
                 ("eval", str(d / "tl"), "--out", str(d / "metrics.json"), "--no-rrd"),
                 ("export", str(d / "tl"), "--onnx", str(d / "m.onnx"))):
        res = CliRunner().invoke(cli, ["-q", *args])
        assert res.exit_code == 0, res.output
    return d


def test_checkpoints_carry_their_provenance(made) -> None:
    data, splits, init = made / "states.h5", made / "splits.json", made / "pre" / "best.pt"
    for name in ("best.pt", "last.pt"):
        prov = load_checkpoint(made / "tl" / name)["provenance"]
        assert (prov["schema"], prov["schema_version"], prov["stage"]) == \
            ("phantom.checkpoint", "1.0", "train")
        assert prov["inputs"] == {str(p): sha256_file(p) for p in (data, splits, init)}
        assert prov["params"]["options"]["epochs"] == 1 and prov["params"]["device"] == "cpu"
        assert prov["params"]["config"]["offsets"] == "heads"     # --recipe ours
        assert prov["params"]["recipe"] == "ours"
        assert isinstance(prov["command"], str) and prov["code_version"]


def test_the_log_keeps_its_provenance_beside_it(made) -> None:
    run = made / "tl"
    assert json.loads((run / "provenance.json").read_text()) == \
        load_checkpoint(run / "last.pt")["provenance"]
    with open(run / "log.csv", newline="") as f:          # a plain CSV, as before
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == LOG_FIELDS and len(rows) == 1


def test_metrics_carry_their_schema_and_provenance(made) -> None:
    doc = validate_metrics(made / "metrics.json")
    assert (doc["schema"], doc["schema_version"]) == (METRICS.name, METRICS.version) == \
        ("phantom.metrics", "1.6")
    prov = doc["provenance"]
    assert (prov["schema"], prov["stage"]) == ("phantom.metrics", "eval")
    best = made / "tl" / "best.pt"
    assert prov["inputs"][str(best)] == sha256_file(best)
    assert set(prov["inputs"]) == {str(best), str(made / "states.h5"), str(made / "splits.json")}
    assert prov["params"] == {"device": "cpu", "scarcity": False, "scarcity_epochs": None,
                              "scarcity_groups": None, "lump": None, "truth": None}


def test_the_onnx_model_carries_its_provenance(made) -> None:
    props = {p.key: p.value for p in onnx.load(str(made / "m.onnx")).metadata_props}
    prov = json.loads(props["provenance"])
    best = made / "tl" / "best.pt"
    assert (prov["schema"], prov["stage"]) == ("phantom.onnx", "export")
    assert prov["inputs"] == {str(best): sha256_file(best)}
    assert {"units", "training_envelope", "point_names"} <= set(props)

"""`pipeline eval --lump`: the test presses over a lump and away from it, each beside the
references, checked against where the presses really are (the states file's tips)."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from core.errors import BadInput
from core.recording import rrd_entities
from data_schema.metrics_doc import validate_metrics
from pipeline.cli import cli
from tests.helpers.cgnn_data import dent_fold
from train.evaluation.lump import LUMP_REACH_M, Lump, parse_lump

TINY = ("--epochs", "1", "--batch", "8", "--device", "cpu", "--no-rrd")


def test_a_press_within_radius_plus_reach_is_over_the_lump():
    lump = Lump(0.05, 0.04, 0.012)
    xy = np.array([[0.05, 0.04], [0.05 + 0.012 + LUMP_REACH_M - 1e-6, 0.04],
                   [0.05, 0.04 + 0.012 + LUMP_REACH_M + 1e-6], [0.0, 0.0]])
    np.testing.assert_array_equal(lump.over(xy), [True, True, False, False])


@pytest.mark.parametrize("text", ["50,40", "50,40,0", "a,b,c", "50,40,-3", "50,nan,12"])
def test_a_malformed_lump_is_refused(text):
    with pytest.raises(BadInput, match="--lump"):
        parse_lump(text)


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> tuple[Path, Path]:
    """A tiny run on the dent model's fold 0."""
    d = tmp_path_factory.mktemp("lump")
    data, splits = dent_fold(d)
    res = CliRunner().invoke(cli, ["-q", "train", "--data", str(data), "--splits", str(splits),
                                   "--out", str(d / "run"), *TINY])
    assert res.exit_code == 0, res.output
    return d, data


def _truth_over(data: Path, splits: Path, lump: Lump) -> int:
    """Test examples of fold 0 whose tip starts within the lump's reach, read from the files
    themselves (not through the evaluation's code)."""
    doc = json.loads(splits.read_text())
    with h5py.File(data) as f:
        tips = f["states/tip"][()]
        count = 0
        for s in ("single", "multi"):
            start = f[f"{s}/start"][()][np.asarray(doc["folds"][0]["test"][s], dtype=int)]
            gap = np.hypot(tips[start, 0] - lump.x, tips[start, 1] - lump.y)
            count += int((gap <= lump.radius + LUMP_REACH_M).sum())
    return count


def test_eval_splits_over_and_away_by_where_the_presses_are(run):
    d, data = run
    test = json.loads((d / "splits.json").read_text())["folds"][0]["test"]["single"]
    with h5py.File(data) as f:                  # where the first test example presses, m
        first = f["states/tip"][int(f["single/start"][test[0]]), :2].astype(float)
    text = f"{first[0] * 1e3:.3f},{first[1] * 1e3:.3f},3"
    lump = parse_lump(text)
    out = d / "metrics.json"
    res = CliRunner().invoke(cli, ["eval", str(d / "run"), "--out", str(out), "--lump", text])
    assert res.exit_code == 0, res.output
    doc = validate_metrics(out)
    row = doc["runs"][0]
    total = row["metrics"]["all"]["n"]
    over = _truth_over(data, d / "splits.json", lump)
    assert 0 < over < total                     # the dent's places: some over, some away
    got = row["lump"]
    assert (got["over"] or {"metrics": {"n": 0}})["metrics"]["n"] == over
    assert (got["away"] or {"metrics": {"n": 0}})["metrics"]["n"] == total - over
    for part in ("over", "away"):
        if got[part] is not None:
            assert set(got[part]["references"]) == set(row["references"])
    assert doc["overall"][0]["lump"]["over"] == got["over"]          # one fold: the same
    assert "Over the lump" in out.with_suffix(".md").read_text()
    assert "/footprint/places" in rrd_entities(out.with_suffix(".rrd"))
    assert "/footprint/lump" in rrd_entities(out.with_suffix(".rrd"))


def test_eval_refuses_two_lumps_in_one_line(run, tmp_path):
    d, data = run
    res = CliRunner().invoke(cli, ["eval", str(d / "run"), "--out", str(tmp_path / "m.json"),
                                   "--lump", "50,50,10", "--truth", str(data)])
    assert res.exit_code == 2 and len(res.output.strip().splitlines()) == 1, res.output

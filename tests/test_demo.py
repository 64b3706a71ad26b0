"""`pipeline demo` runs every stage end to end, leaves each output and recording readable, and
skips what did not change."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
from click.testing import CliRunner

from core.recording import rrd_entities
from data_schema import validate_h5
from data_schema.json_docs import validate_folds
from data_schema.states import validate_states
from data_schema.synced import SYNCED
from ingest.mcap_io import read_raw_mcap
from pipeline.cli import cli
from pipeline.demo_plan import PAPER_NETWORK, SMOKE, demo_steps


def test_demo_runs_every_stage_and_skips_unchanged_ones(tmp_path):
    out = tmp_path / "demo"
    res = CliRunner().invoke(cli, ["-q", "demo", "--smoke", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert (out / "session" / "truth.h5").is_file()
    raw = read_raw_mcap(out / "session.mcap")
    assert len(raw.phantom_markers) == 25 and len(raw.indenter_markers) == 4
    validate_h5(out / "session_synced.h5", SYNCED)
    for states in ("session_states.h5", "calibration_states.h5", "msm.h5"):
        validate_states(out / states)
    assert len(validate_folds(out / "splits.json")["folds"]) == 2
    fit = json.loads((out / "msm_params.json").read_text())
    assert fit["mean_distance_m"] < fit["still_distance_m"]
    with h5py.File(out / "msm.h5") as f:                      # the lab's 25 markers + the tip
        assert f["states/points"].shape[1] == 26 and "layout" in f.attrs
    metrics = json.loads((out / "metrics.json").read_text())
    assert {Path(r["run"]).name for r in metrics["runs"]} == {
        "msm", "exp_tl_fold0", "exp_tl_fold1", "exp_notl_fold0", "exp_notl_fold1"}
    assert all(set(r["references"]) == {"nothing moves", "nearest press", "force, linear"}
               for r in metrics["runs"])
    assert "*reference: nearest press*" in (out / "metrics.md").read_text()
    scarcity = json.loads((out / "scarcity" / "fold0.json").read_text())["scarcity"]
    assert {r["predictor"] for r in scarcity} >= {"TL", "no TL", "nearest press"}
    for rrd in ("session/recording.rrd", "session.rrd", "session_synced.rrd",
                "session_states.rrd", "splits.rrd", "msm_params.rrd", "msm.rrd",
                "runs/msm/train.rrd", "metrics.rrd"):
        assert rrd_entities(out / rrd), rrd
    for line in res.output.splitlines():                  # sync and the fit met their targets
        if line.strip().startswith("MISSED"):
            assert "sync" not in line and "fitted MSM" not in line, line
    assert "transfer learning, pooled over folds" in res.output
    again = CliRunner().invoke(cli, ["-q", "demo", "--smoke", "--out", str(out)])
    assert again.exit_code == 0, again.output
    steps = demo_steps(out, 0, SMOKE)
    assert again.output.count("(unchanged since its last run: skipped)") == len(steps)


def test_no_tip_offsets_trains_the_papers_network_with_the_rest_of_the_recipe(tmp_path):
    """``--no-tip-offsets`` changes every training run's network and nothing else."""
    ours = demo_steps(tmp_path, 0, SMOKE)
    paper = demo_steps(tmp_path, 0, SMOKE, recipe=PAPER_NETWORK)
    trains = [(a.args, b.args) for a, b in zip(ours, paper, strict=True) if a.args[0] == "train"]
    assert len(trains) == 1 + 2 * SMOKE.folds
    for with_offsets, without in trains:
        assert "--tip-offsets" in with_offsets and "--tip-offsets" not in without
        assert [a for a in with_offsets if a != "--tip-offsets"] == list(without)
    assert [a.args for a in ours if a.args[0] != "train"] == \
        [b.args for b in paper if b.args[0] != "train"]

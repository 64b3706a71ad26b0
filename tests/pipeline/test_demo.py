"""`pipeline demo` runs every stage end to end, leaves each output and recording readable, and
skips what did not change."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import pytest
import torch
from click.testing import CliRunner

from core.recording import rrd_entities
from data_schema import validate_h5
from data_schema.json_docs import validate_folds
from data_schema.states import validate_states
from data_schema.synced import SYNCED
from ingest.mcap_io import read_raw_mcap
from pipeline.cli import cli
from pipeline.demo_plan import NETWORKS, RECIPE, SMOKE, demo_steps


def test_demo_runs_every_stage_and_skips_unchanged_ones(tmp_path):
    out = tmp_path / "demo"
    res = CliRunner().invoke(cli, ["-q", "demo", "--smoke", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert (out / "session" / "truth.h5").is_file()
    raw = read_raw_mcap(out / "session.mcap")
    assert len(raw.phantom_markers) == 25 and len(raw.indenter_markers) == 4
    validate_h5(out / "session_synced.h5", SYNCED)
    validate_states(out / "session_states.h5")
    folds = validate_folds(out / "splits.json")["folds"]
    assert len(folds) == 2
    for k, fold in enumerate(folds):                      # the MSM fitted per fold ...
        d = out / "msm" / f"fold{k}"
        fit = json.loads((d / "params.json").read_text())
        assert fit["mean_distance_m"] < fit["still_distance_m"]
        fitted = {s["sequence"] for s in fit["per_sequence"]}   # ... on its training presses
        assert fitted and fitted <= set(fold["train"]["groups"])
        assert not fitted & set(fold["test"]["groups"])
        validate_states(d / "msm.h5")
        with h5py.File(d / "msm.h5") as f:                 # the lab's 25 markers + the tip
            assert f["states/points"].shape[1] == 26 and "layout" in f.attrs
    metrics = json.loads((out / "metrics.json").read_text())
    assert {Path(r["run"]).name for r in metrics["runs"]} == {
        "msm_fold0", "msm_fold1", "exp_tl_fold0", "exp_tl_fold1", "exp_notl_fold0",
        "exp_notl_fold1"}
    for k in range(2):                                    # TL starts from its own fold's MSM
        meta = torch.load(out / "runs" / f"exp_tl_fold{k}" / "best.pt", weights_only=False)
        assert Path(meta["meta"]["init"]).parent.name == f"msm_fold{k}"
    assert all(set(r["references"]) == {"nothing moves", "nearest press", "force, linear"}
               for r in metrics["runs"])
    md = (out / "metrics.md").read_text()
    assert "*reference: nearest press*" in md
    per_fold = md[md.index("Mean L_d per fold on Exp"):].splitlines()   # the lab's folds ...
    assert "cGNN/rot MSM" not in per_fold[2] and "cGNN/MSM (TL)" in per_fold[2]   # ... only
    scarcity = json.loads((out / "scarcity" / "fold0.json").read_text())["scarcity"]
    assert {r["predictor"] for r in scarcity} >= {"TL", "no TL", "nearest press"}
    for rrd in ("session/recording.rrd", "session.rrd", "session_synced.rrd",
                "session_states.rrd", "splits.rrd", "msm/fold0/params.rrd", "msm/fold1/msm.rrd",
                "runs/msm_fold0/train.rrd", "metrics.rrd"):
        assert rrd_entities(out / rrd), rrd
    for line in res.output.splitlines():                  # sync met its targets
        if line.strip().startswith("MISSED"):
            assert "sync" not in line, line
    assert "transfer learning, pooled over folds" in res.output
    steps = demo_steps(out, 0, SMOKE)
    times = json.loads((out / "demo_times.json").read_text())     # every step timed, once
    assert sorted(tuple(s["args"]) for s in times["steps"]) == sorted(s.args for s in steps)
    assert not any(s["skipped"] for s in times["steps"])
    trains = [s for s in times["steps"] if s["stage"] == "train"]
    assert len(trains) == 3 * SMOKE.folds and all(s["seconds"] > 0 for s in trains)
    assert times["stages"]["train"]["ran"] == len(trains)
    assert times["host_speed_s"] is None and times["host_speed"].startswith("absent")
    again = CliRunner().invoke(cli, ["-q", "demo", "--smoke", "--out", str(out)])
    assert again.exit_code == 0, again.output
    assert again.output.count("(unchanged since its last run: skipped)") == len(steps)
    times = json.loads((out / "demo_times.json").read_text())
    assert all(s["skipped"] and s["seconds"] == 0 for s in times["steps"])
    (out / "msm" / "fold0" / "params.json").unlink()    # one fold's fit gone: what reads it,
    third = CliRunner().invoke(cli, ["-q", "demo", "--smoke", "--out", str(out)])   # and on
    assert third.exit_code == 0, third.output
    lines = third.output.splitlines()
    rerun = [line for line, after in zip(lines, lines[1:] + [""], strict=True)
             if "$ pipeline" in line and "skipped" not in after]
    for name in ("fold0/params.json", "fold0/msm.h5", "fold0/splits.json", "msm_fold0 ",
                 "exp_tl_fold0 ", "metrics.json"):
        assert any(name in line for line in rerun), name
    assert not any("fold1" in line for line in rerun if "pipeline eval" not in line), rerun


@pytest.mark.parametrize("network", list(NETWORKS))
def test_network_changes_every_training_runs_network_and_nothing_else(tmp_path, network):
    """``--network`` adds its flags after the recipe's to every training run (pre-training
    and both fine-tunings); every other step is the same."""
    ours = demo_steps(tmp_path, 0, SMOKE)
    other = demo_steps(tmp_path, 0, SMOKE, recipe=NETWORKS[network])
    trains = [(a.args, b.args) for a, b in zip(ours, other, strict=True) if a.args[0] == "train"]
    assert len(trains) == 3 * SMOKE.folds                  # pre-training and two fine-tunings
    extra = NETWORKS[network][len(RECIPE):]
    for plain, changed in trains:
        at = plain.index(RECIPE[-1]) + 1
        assert changed == (*plain[:at], *extra, *plain[at:])
    assert [a.args for a in ours if a.args[0] != "train"] == \
        [b.args for b in other if b.args[0] != "train"]


def test_demo_runs_on_another_labs_phantom(tmp_path):
    """A 120 x 80 mm block with 12 scattered markers at 250 Hz: every stage takes its points,
    footprint and rate, from synth to eval (the wiring; --smoke learns nothing)."""
    out = tmp_path / "lab"
    res = CliRunner().invoke(cli, ["-q", "demo", "--smoke", "--out", str(out), "--markers",
                                   "scattered:12", "--size", "120x80", "--mocap-rate", "250"])
    assert res.exit_code == 0, res.output
    raw = read_raw_mcap(out / "session.mcap")
    assert len(raw.phantom_markers) == 12 and raw.markers.rate_hz == 250
    names = [*raw.phantom_markers, "tip"]
    for states in (out / "session_states.h5", out / "msm" / "fold1" / "msm.h5"):
        with h5py.File(states) as f:
            assert f["states/points"].shape[1] == 13
            assert json.loads(f.attrs["point_names"]) == names
            assert tuple(f.attrs["footprint_m"]) == pytest.approx((0.12, 0.08))
    fit = json.loads((out / "msm" / "fold0" / "params.json").read_text())["msm_params"]
    assert (fit["size"], fit["size_y"]) == pytest.approx((0.12, 0.08))
    assert len(json.loads((out / "metrics.json").read_text())["runs"]) == 6

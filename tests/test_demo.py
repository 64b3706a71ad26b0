"""`pipeline demo` runs every stage end to end, leaves each output and recording readable, and
skips what did not change."""

from __future__ import annotations

import json

from click.testing import CliRunner

from core.recording import rrd_entities
from data_schema import validate_h5
from data_schema.json_docs import validate_folds
from data_schema.states import validate_states
from data_schema.synced import SYNCED
from ingest.mcap_io import read_raw_mcap
from pipeline.cli import cli
from pipeline.demo_plan import SMOKE, demo_steps


def test_demo_runs_every_stage_and_skips_unchanged_ones(tmp_path):
    out = tmp_path / "demo"
    res = CliRunner().invoke(cli, ["-q", "demo", "--smoke", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert (out / "session" / "truth.h5").is_file()
    raw = read_raw_mcap(out / "session.mcap")
    assert len(raw.phantom_markers) == 25 and len(raw.indenter_markers) == 4
    validate_h5(out / "synced.h5", SYNCED)
    for states in ("states.h5", "msm.h5"):
        validate_states(out / states)
    assert len(validate_folds(out / "splits.json")["folds"]) == 2
    labels = {r["label"] for r in json.loads((out / "metrics.json").read_text())["overall"]}
    assert labels == {"cGNN/aug MSM", "cGNN/aug MSM (TL)", "cGNN/Exp", "cGNN/rot Exp"}
    for rrd in ("session/recording.rrd", "session.rrd", "synced.rrd", "states.rrd",
                "splits.rrd", "msm.rrd", "runs/msm/train.rrd", "metrics.rrd"):
        assert rrd_entities(out / rrd), rrd
    assert "MISSED" not in res.output.split("transfer learning")[0]   # sync met its targets
    assert "rotation augmentation cuts it by" in res.output
    again = CliRunner().invoke(cli, ["-q", "demo", "--smoke", "--out", str(out)])
    assert again.exit_code == 0, again.output
    steps = demo_steps(out, 0, SMOKE)
    assert again.output.count("(unchanged since its last run: skipped)") == len(steps)

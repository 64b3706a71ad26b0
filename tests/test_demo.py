"""`pipeline demo` runs every stage end to end and leaves each output and recording readable."""

from __future__ import annotations

from click.testing import CliRunner

from core.recording import rrd_entities
from data_schema import validate_h5
from data_schema.states import STATES
from data_schema.synced import SYNCED
from ingest.mcap_io import read_raw_mcap
from pipeline.cli import cli


def test_demo_runs_every_stage(tmp_path):
    out = tmp_path / "demo"
    res = CliRunner().invoke(cli, ["-q", "demo", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert (out / "session" / "truth.h5").is_file()
    raw = read_raw_mcap(out / "session.mcap")
    assert len(raw.phantom_markers) == 25 and len(raw.indenter_markers) == 4
    validate_h5(out / "synced.h5", SYNCED)
    validate_h5(out / "msm.h5", STATES)
    for rrd in ("session/recording.rrd", "session.rrd", "synced.rrd", "msm.rrd"):
        assert rrd_entities(out / rrd), rrd
    assert "OVER" not in res.output    # sync met every accuracy target against the truth

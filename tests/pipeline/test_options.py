"""An option its own command would refuse later is refused as the command line is parsed: exit
status 2, one line naming the option, nothing written, the stage never reached. The checks the
stages make of their settings stay, for callers of the library, with the same bounds."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from core.errors import BadInput
from pipeline.cli import cli
from sim.msm.msm_protocol import Protocol, parse_shard
from sim.twin.marker_layout import parse_layout, parse_size
from sim.twin.twin_scene import TwinParams
from sim.twin.twin_scene import check_params as check_twin
from split.split import make_folds
from split.split_params import SplitParams
from sync.sync_params import SyncParams
from sync.sync_params import check_params as check_sync

# where each command hands over to its stage: reaching it means the option was not refused
STAGES = {"synth": "sim.twin.synth_stage.run_synth", "sync": "sync.sync_stage.run_sync",
          "extract": "extract.extract_stage.run_extract", "split": "split.split_stage.run_split",
          "simulate": "sim.msm.simulate_stage.run_simulate",
          "fit-msm": "sim.msm.fit_msm_stage.run_fit_msm", "demo": "pipeline.demo_cmd.demo_steps"}
INPUT = "in.bin"          # the file argument: it exists; the stage that would read it is never run

CASES = [
    ("synth", ["--mocap-rate", "5"], "--mocap-rate"),
    ("synth", ["--mocap-rate", "2500"], "--mocap-rate"),
    ("synth", ["--drift", "2000"], "--drift"),
    ("synth", ["--offset", "-4000"], "--offset"),
    ("synth", ["--press-seconds", "nan"], "--press-seconds"),
    ("synth", ["--pivot-seconds", "1"], "--pivot-seconds"),
    ("synth", ["--marker-pitch", "6"], "--marker-pitch"),
    ("synth", ["--markers", "five"], "--markers"),
    ("synth", ["--markers", "scattered:3"], "--markers"),
    ("synth", ["--size", "20x20"], "--size"),
    ("synth", ["--locations", "11"], "--locations"),
    ("synth", ["--view-press", "-1"], "--view-press"),
    ("demo", ["--size", "400x80"], "--size"),
    ("demo", ["--mocap-rate", "5"], "--mocap-rate"),
    ("demo", ["--marker-pitch", "6"], "--marker-pitch"),
    ("demo", ["--markers", "1x5"], "--markers"),
    ("sync", [INPUT, "--max-gap-ms", "nan"], "--max-gap-ms"),
    ("sync", [INPUT, "--margin-s", "-1"], "--margin-s"),
    ("sync", [INPUT, "--location-radius-mm", "0"], "--location-radius-mm"),
    ("extract", [INPUT, "--max-speed", "nan"], "--max-speed"),
    ("extract", [INPUT, "--half-window-ms", "0"], "--half-window-ms"),
    ("split", [INPUT, "--folds", "0"], "--folds"),
    ("split", [INPUT, "--ratio", "1:2"], "--ratio"),
    ("split", [INPUT, "--ratio", "0:1:1"], "--ratio"),
    ("simulate", ["--contact-radius", "0.05"], "--contact-radius"),
    ("simulate", ["--max-angle", "91"], "--max-angle"),
    ("simulate", ["--shard", "2/2"], "--shard"),
    ("simulate", ["--shard", "x"], "--shard"),
    ("fit-msm", [INPUT, "--contact-radius", "0.05"], "--contact-radius"),
    ("fit-msm", [INPUT, "--start", "0.5", "21"], "--start"),
    ("fit-msm", [INPUT, "--start", "100", "1e6"], "--start"),
]


@pytest.mark.parametrize("command, args, option", CASES,
                         ids=[f"{c} {' '.join(a[a.index(o):])}" for c, a, o in CASES])
def test_refused_as_the_command_line_is_parsed(tmp_path, monkeypatch, command, args, option):
    def reached(*_args, **_kwargs):
        raise AssertionError(f"{command} reached its stage with {args}")

    monkeypatch.setattr(STAGES[command], reached)
    monkeypatch.chdir(tmp_path)
    Path(INPUT).write_bytes(b"never read")
    out = "out" if command in ("synth", "demo") else "out.h5"
    res = CliRunner().invoke(cli, ["-q", command, *(["--out", out] if command != "synth"
                                                   else [out]), *args])
    assert res.exit_code == 2, (res.output, res.exception)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {option}"), res.stderr
    assert lines[0][len(f"error: {option}")] in " :", lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == [INPUT]


def test_the_contact_radius_bound_is_the_protocols():
    """0.05 m is excluded by both; just below it is taken by both."""
    res = CliRunner().invoke(cli, ["simulate", "--out", "x.h5", "--contact-radius", "0.05"])
    assert "must be in [0, 0.05) m" in res.stderr
    with pytest.raises(BadInput, match=r"\[0, 0.05\) m"):
        Protocol(contact_radius=0.05).check(1024)
    Protocol(contact_radius=0.0499).check(1024)


@pytest.mark.parametrize("check", [
    lambda: Protocol(max_angle_deg=91.0).check(1024),
    lambda: parse_shard("2/2"),
    lambda: check_sync(SyncParams(max_gap_s=math.nan)),
    lambda: check_sync(SyncParams(location_radius_m=0.0)),
    lambda: check_twin(TwinParams(rate_hz=5.0)),
    lambda: check_twin(TwinParams(drift_ppm=2000.0)),
    lambda: parse_layout("five"),
    lambda: parse_size("20x20"),
    lambda: make_folds(np.arange(6), SplitParams("sequence", (1, 1, 1), folds=0)),
])
def test_the_stages_still_check_their_settings(check):
    with pytest.raises(BadInput):
        check()

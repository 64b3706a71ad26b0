"""The analog board's volts: an F/T interface's calibrated analog output arrives as
volts; session.toml's per-channel ``scale`` (N/V, N m/V) and ``offset`` turn it into N and N m,
and its ``units`` name the units of an export that states none. Checked on the real Qualisys
C3D export against its own bytes, and on QTM analog TSV exports; ``inspect`` lists an analog
export's channels."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from helpers.c3d_bytes import QUALISYS_C3D, qualisys_analog

from core.errors import BadInput
from data_schema.session import read_session
from ingest.force_source import read_force
from pipeline.cli import cli

SCALE = [500.0, 500.0, 1000.0, 40.0, 40.0, 20.0]        # N/V and N m/V of an F/T interface
OFFSET = [0.002, -0.001, 0.0, 0.0005, 0.0, -0.0025]     # V at no load
WRENCH_UNITS = ["N", "N", "N", "N*m", "N*m", "N*m"]


def _session(folder: Path, force_file: str, extra: str) -> Path:
    """A session folder whose [force] reads ``force_file`` with the keys in ``extra``."""
    (folder / "trial.tsv").write_text("")
    (folder / "session.toml").write_text(
        '[mocap]\nfile = "trial.tsv"\nphantom_markers = ["A", "B", "C", "D"]\n'
        'indenter_markers = ["I1", "I2", "I3"]\n'
        f'[force]\nfile = "{force_file}"\nkind = "wrench"\n{extra}\n')
    return folder


def test_real_c3d_volts_scaled_to_newtons(real_samples, tmp_path):
    """The real export's force plate FP1 channels 1-6 are in V: (V - offset) x scale, against
    the C3D standard's value computed from the file's own bytes."""
    raw_bytes = (real_samples / QUALISYS_C3D).read_bytes()
    (tmp_path / "trial.c3d").write_bytes(raw_bytes)
    _session(tmp_path, "trial.c3d", "channels = [1, 2, 3, 4, 5, 6]\n"
             'units = "N,N,N,N*m,N*m,N*m"\n'
             f"scale = {SCALE}\noffset = {OFFSET}")
    s = read_force(read_session(tmp_path).force)
    raw, scale, offset, gen = qualisys_analog(raw_bytes)
    volts = (raw[:, :6] - offset[:6]) * scale[:6] * gen
    np.testing.assert_allclose(s.values, (volts - OFFSET) * SCALE, rtol=1e-6, atol=1e-9)
    assert s.units == WRENCH_UNITS and s.channels[0] == "FP1_FX"
    assert s.meta["units_in_file"] == ["V"] * 6 and s.meta["scale"] == SCALE


def test_real_c3d_volts_without_scale_refused_for_a_wrench(real_samples, tmp_path):
    (tmp_path / "trial.c3d").write_bytes((real_samples / QUALISYS_C3D).read_bytes())
    _session(tmp_path, "trial.c3d", "channels = [1, 2, 3, 4, 5, 6]")
    with pytest.raises(BadInput, match="'FP1_FX' is in V, which does not fit force.kind = "
                                       r"'wrench' \(give force.scale"):
        read_force(read_session(tmp_path).force)


_VOLTS = np.array([[0.10, -0.20, 0.30, 0.01, -0.02, 0.03],
                   [0.11, -0.21, 0.31, 0.02, -0.03, 0.04],
                   [0.12, -0.22, 0.32, 0.03, -0.04, 0.05],
                   [0.13, -0.23, 0.33, 0.04, -0.05, 0.06]])


def _qtm_analog(path: Path, unit_line: str | None = None) -> Path:
    """A QTM analog TSV export of six channels, with or without a CHANNEL_UNITS line."""
    names = [f"Nano17 G{k}" for k in range(6)]
    head = ["NO_OF_SAMPLES\t4", "TOT_NO_OF_CHAN\t6", "FREQUENCY\t1000",
            "DATA_INCLUDED\tANALOG", "CHANNEL_NAMES\t" + "\t".join(names),
            "CHANNEL_GAIN\t" + "\t".join(["1"] * 6)]
    if unit_line:
        head.append("CHANNEL_UNITS\t" + "\t".join([unit_line] * 6))
    rows = ["\t".join(f"{x:.2f}" for x in r) for r in _VOLTS]
    path.write_text("\r\n".join(head + rows) + "\r\n", newline="")
    return path


def test_qtm_analog_without_a_unit_line_takes_session_units(tmp_path):
    """A 36-marker lab's export states no unit: session.toml's units (here N and N m: the
    interface outputs the wrench directly) or its scale apply."""
    _qtm_analog(tmp_path / "trial_a.tsv")
    _session(tmp_path, "trial_a.tsv", "channels = [1, 2, 3, 4, 5, 6]\n"
             'units = "N,N,N,N-mm,N-mm,N-mm"')
    s = read_force(read_session(tmp_path).force)
    np.testing.assert_allclose(s.values, _VOLTS * [1, 1, 1, 1e-3, 1e-3, 1e-3], atol=1e-15)
    assert s.units == WRENCH_UNITS and s.meta["clock"] == "mocap"
    _session(tmp_path, "trial_a.tsv", "channels = [1, 2, 3, 4, 5, 6]\n"
             'units = "N,N,N,N*m,N*m,N*m"\n'
             f"scale = {SCALE}\noffset = {OFFSET}")
    s = read_force(read_session(tmp_path).force)
    np.testing.assert_allclose(s.values, (_VOLTS - OFFSET) * SCALE, rtol=1e-12)


def test_qtm_analog_stating_volts_contradicting_session_units_is_refused(tmp_path):
    _qtm_analog(tmp_path / "trial_a.tsv", "mV")
    _session(tmp_path, "trial_a.tsv", "channels = [1, 2, 3, 4, 5, 6]\n"
             'units = "N,N,N,N*m,N*m,N*m"')
    with pytest.raises(BadInput, match="is in mV as the file states, but force.units says N"):
        read_force(read_session(tmp_path).force)
    _session(tmp_path, "trial_a.tsv", "channels = [1, 2, 3, 4, 5, 6]\n"
             f"scale = {SCALE}")                      # mV taken to V before the N/V scale
    s = read_force(read_session(tmp_path).force)
    np.testing.assert_allclose(s.values, _VOLTS * 1e-3 * SCALE, rtol=1e-12)


@pytest.mark.parametrize("extra, words", [
    ("scale = [1.0, 2.0]", "force.scale must be a number or 6 numbers"),
    ("scale = 0", "force.scale must not be 0"),
    ('offset = "x"', "force.offset must be a number or 6 numbers"),
    ('delimiter = "::"', "force.delimiter must be one of"),
    ('decimal = ";"', "force.decimal must be one of"),
])
def test_bad_scale_and_dialect_keys_refused_by_session(tmp_path, extra, words):
    _qtm_analog(tmp_path / "trial_a.tsv")
    _session(tmp_path, "trial_a.tsv", f"channels = [1, 2, 3, 4, 5, 6]\n{extra}")
    with pytest.raises(BadInput, match=words):
        read_session(tmp_path)


def test_log_keys_for_an_analog_export_are_refused(tmp_path):
    _qtm_analog(tmp_path / "trial_a.tsv")
    _session(tmp_path, "trial_a.tsv", 'channels = [1, 2, 3, 4, 5, 6]\nvariable = "x"')
    with pytest.raises(BadInput, match="force.variable is for force logs"):
        read_force(read_session(tmp_path).force)


def test_inspect_fills_channels_for_analog_exports(real_samples, tmp_path):
    for path in (real_samples / QUALISYS_C3D, _qtm_analog(tmp_path / "t_a.tsv")):
        res = CliRunner().invoke(cli, ["inspect", str(path), "--json"])
        assert res.exit_code == 0, res.stderr
        s = json.loads(res.output)
        assert s["channels"] == [c["name"] for c in s["analog"]["channels"]]
        assert len(s["channels"]) == (69 if path.suffix == ".c3d" else 6)

"""Force through the mocap system's analog board: the real C3D export's ANALOG section against
its own bytes (scales applied once, as the C3D standard says), channel names from LABELS or
DESCRIPTIONS, QTM analog TSV exports, the whole pipeline on the twin's analog route against its
truth, and the refusals (one line, exit 2, nothing written)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner
from helpers.c3d_bytes import FRAMES, QUALISYS_C3D, qualisys_analog, rename_parameter, set_parameter
from helpers.spoiled_session import ingest_spoiled
from helpers.staged_twin import shared_clock_checked, staged_twin
from helpers.truth_checks import check_states_against_truth

from core.errors import BadInput
from ingest.analog import analog_force, channel_names, resolve_channels
from ingest.c3d import read_c3d, read_c3d_analog
from ingest.detect import detect_format, read_analog
from ingest.inspect_stage import run_inspect
from ingest.qtm_analog import read_qtm_analog
from pipeline.cli import cli

AMTI = [f"Amti Gen 5 OR6-5-1000 3581_{k}" for k in range(1, 7)]   # a force plate, channels 58-63


def _cli(*args: object):
    return CliRunner().invoke(cli, ["-q", *map(str, args)])


# ---------------------------------------------------------------------------- the real C3D


def _patched(real_samples: Path, tmp_path: Path, *edits: Callable[[bytearray], None]) -> Path:
    data = bytearray((real_samples / QUALISYS_C3D).read_bytes())
    for edit in edits:
        edit(data)
    out = tmp_path / "patched.c3d"
    out.write_bytes(bytes(data))
    return out


def test_real_c3d_analog_section(real_samples):
    """Rate, names, units and scales as the file states them; values = (raw - OFFSET) x SCALE x
    GEN_SCALE of the raw bytes (EMG channels scaled by 1e-6, the AMTI plate by -1)."""
    a = read_c3d_analog(real_samples / QUALISYS_C3D)
    raw, scale, offset, gen = qualisys_analog((real_samples / QUALISYS_C3D).read_bytes())
    assert (a.rate_hz, a.point_rate_hz, a.samples, len(a.names)) == (2000, 200, 3400, 69)
    assert a.names[:6] == ["FP1_FX", "FP1_FY", "FP1_FZ", "FP1_MX", "FP1_MY", "FP1_MZ"]
    assert a.names[40] == "EMG 1" and a.names[56] == "Sync" and a.names[57:63] == AMTI
    assert a.units[57:63] == ["N", "N", "N", "Nmm", "Nmm", "Nmm"] and a.units[0] == "V"
    assert scale[40] == pytest.approx(1e-6) and scale[57] == -1 and gen == 1
    np.testing.assert_array_equal(a.scales, scale)
    np.testing.assert_allclose(a.values, (raw - offset) * scale * gen, rtol=1e-6, atol=1e-12)


def test_scales_are_applied_once_as_the_standard_says(real_samples, tmp_path):
    """GEN_SCALE 2 and non-zero OFFSETs written into the real file: the values follow the
    standard's formula on the raw bytes, so neither ezc3d nor we apply a scale twice."""
    path = _patched(real_samples, tmp_path,
                    lambda d: set_parameter(d, "ANALOG", "GEN_SCALE", 2.0),
                    lambda d: set_parameter(d, "ANALOG", "OFFSET", 100, index=0),
                    lambda d: set_parameter(d, "ANALOG", "OFFSET", -7, index=40))
    a = read_c3d_analog(path)
    raw, scale, offset, gen = qualisys_analog(path.read_bytes())
    assert gen == 2.0 and offset[0] == 100 and offset[40] == -7
    np.testing.assert_allclose(a.values, (raw - offset) * scale * gen, rtol=1e-6, atol=1e-12)
    assert a.values[0, 0] == pytest.approx((raw[0, 0] - 100) * 2, rel=1e-6)
    assert a.gen_scale == 2.0 and a.offsets[0] == 100


def test_real_force_plate_as_a_wrench(real_samples):
    """The AMTI plate's six channels by name or by number: N stay N, N mm become N m."""
    a = read_c3d_analog(real_samples / QUALISYS_C3D)
    raw, scale, _, _ = qualisys_analog((real_samples / QUALISYS_C3D).read_bytes())
    by_name = analog_force(a, AMTI, "wrench", rate_hz=2000.0)
    by_number = analog_force(a, list(range(58, 64)), "wrench")
    expected = raw[:, 57:63] * scale[57:63] * [1, 1, 1, 1e-3, 1e-3, 1e-3]
    np.testing.assert_allclose(by_name.values, expected, rtol=1e-6, atol=1e-12)
    np.testing.assert_array_equal(by_number.values, by_name.values)
    assert by_name.units == ["N", "N", "N", "N*m", "N*m", "N*m"]
    assert by_name.meta["clock"] == "mocap" and by_name.time_ns[10] == 5_000_000
    with pytest.raises(BadInput, match="fit force.kind = 'gauge'"):
        analog_force(a, AMTI, "gauge")


def test_real_file_inspect_lists_analog_channels(real_samples):
    s = run_inspect(real_samples / QUALISYS_C3D)
    a = s["analog"]
    assert (a["rate_hz"], a["samples_per_frame"], len(a["channels"])) == (2000, 10, 69)
    emg = a["channels"][40]
    assert (emg["number"], emg["name"], emg["units"]) == (41, "EMG 1", "V")
    assert emg["scale"] == pytest.approx(1e-6) and emg["offset"] == 0
    assert a["channels"][59]["units"] == "N" and a["channels"][60]["scale"] == -1


@pytest.mark.parametrize("edit, words", [
    (lambda d: set_parameter(d, "ANALOG", "SCALE", 0.0, index=3),
     "ANALOG:SCALE of analog channel 4 is 0, not a scale factor"),
    (lambda d: set_parameter(d, "ANALOG", "GEN_SCALE", 0.0),
     "ANALOG:GEN_SCALE of analog channel 1 is 0"),
    (lambda d: rename_parameter(d, "ANALOG", "GEN_SCALE", "GEN_SCALX"),
     "ANALOG:GEN_SCALE is missing"),
    (lambda d: set_parameter(d, "ANALOG", "RATE", 1999.0),
     "analog rate 1999 Hz is not a whole multiple of the point rate 200 Hz"),
])
def test_real_file_with_bad_analog_parameters_is_refused(real_samples, tmp_path, edit, words):
    path = _patched(real_samples, tmp_path, edit)
    with pytest.raises(BadInput, match=words):
        read_c3d_analog(path)
    assert read_c3d(path).frames == FRAMES          # the markers are still readable


@pytest.mark.parametrize("name", ["SCALE", "OFFSET"])
def test_missing_scale_or_offset_is_refused_before_ezc3d_reads(real_samples, tmp_path, name):
    """ezc3d 1.7 segfaults on analog channels without ANALOG:SCALE or OFFSET: both readers
    refuse such a file from the parameter section, before ezc3d sees it."""
    path = _patched(real_samples, tmp_path,
                    lambda d: rename_parameter(d, "ANALOG", name, name[:-1] + "X"))
    for read in (read_c3d, read_c3d_analog):
        with pytest.raises(BadInput, match=f"ANALOG:{name} is missing"):
            read(path)


# ---------------------------------------------------------------------------- names


def test_names_come_from_descriptions_where_labels_are_cut_or_repeated():
    labels = ["Fz", "Fz", "Nano17 G", "Sync", "EMG", "EMG"]
    descriptions = ["Plate 1 Fz", "Plate 2 Fz", "Nano17 Gauge 0", "trigger line", "", ""]
    assert channel_names(labels, descriptions) == [
        "Plate 1 Fz", "Plate 2 Fz", "Nano17 Gauge 0",   # repeated; cut short
        "Sync",                                          # a label of its own: kept
        "EMG", "EMG"]                                    # repeated, nothing better: kept


def test_resolving_channels(real_samples):
    a = read_c3d_analog(real_samples / QUALISYS_C3D)
    assert resolve_channels(a, ["Sync", 1, "EMG 16"]) == [56, 0, 55]
    with pytest.raises(BadInput, match="'Nano17 G0' .*is not in the file"):
        resolve_channels(a, ["Nano17 G0"])
    with pytest.raises(BadInput, match="channel number 70 is not in the file"):
        resolve_channels(a, [70])
    a.labels[1] = a.labels[0]                      # two channels named FP1_FX, no description
    a.descriptions[0] = a.descriptions[1] = ""
    with pytest.raises(BadInput, match="'FP1_FX' .*names several channels"):
        resolve_channels(a, ["FP1_FX"])


# ---------------------------------------------------------------------------- QTM analog TSV

_OLD_TSV = ("NO_OF_SAMPLES\t4\r\nTOT_NO_OF_CHAN\t3\r\nFREQUENCY\t1000\r\n"
            "TIME_STAMP\t2012-03-01, 10:00:00\t100.5\r\nDESCRIPTION\t--\r\n"
            "DATA_INCLUDED\tANALOG\r\nCHANNEL_NAMES\tFx\tFy\tFz\r\nCHANNEL_GAIN\t1\t1\t1\r\n"
            "0.10\t-0.20\t0.30\r\n0.11\t-0.21\t0.31\r\n0.12\t-0.22\t0.32\r\n"
            "0.13\t-0.23\t0.33\r\n")


def test_qtm_analog_tsv_old_layout(tmp_path):
    """An export without FILE_VERSION, SAMPLE or TIME columns: names, rate and values."""
    path = tmp_path / "trial_a.tsv"
    path.write_text(_OLD_TSV, newline="")
    assert detect_format(path) == "qtm_tsv_analog"
    a = read_analog(path)
    assert a.names == ["Fx", "Fy", "Fz"] and a.rate_hz == 1000 and a.units == ["V"] * 3
    np.testing.assert_allclose(a.values[:, 1], [-0.20, -0.21, -0.22, -0.23])
    assert list(a.time_ns()) == [0, 1_000_000, 2_000_000, 3_000_000]


@pytest.mark.parametrize("old, new, words", [
    ("NO_OF_SAMPLES\t4", "NO_OF_SAMPLES\t5", "line 1: NO_OF_SAMPLES says 5 samples but the "
                                             "file has 4 rows"),
    ("CHANNEL_GAIN\t1\t1\t1", "CHANNEL_GAIN\t1\t0\t1",
     "CHANNEL_GAIN of analog channel 2 is 0, not a scale factor"),
    ("TOT_NO_OF_CHAN\t3", "TOT_NO_OF_CHAN\t4", "TOT_NO_OF_CHAN is 4 but CHANNEL_NAMES lists 3"),
    ("0.12\t-0.22", "0.12\tNaN", "line 11: analog channel 2 has no value"),
    ("FREQUENCY\t1000", "FREQUENCY\t1000\r\nCHANNEL_FREQUENCIES\t1000\t1000\t500",
     "CHANNEL_FREQUENCIES differ between channels"),
])
def test_qtm_analog_tsv_that_cannot_be_right(tmp_path, old, new, words):
    path = tmp_path / "trial_a.tsv"
    path.write_text(_OLD_TSV.replace(old, new), newline="")
    with pytest.raises(BadInput, match=words):
        read_qtm_analog(path)


# ---------------------------------------------------------------------------- the twin


@pytest.fixture(scope="module", params=["tsv", "c3d"])
def analog_session(request, tmp_path_factory) -> Path:
    """A twin session with the force through the analog board (QTM analog TSV, or one C3D with
    markers and force), ingested, synced and extracted."""
    return staged_twin(tmp_path_factory.mktemp(f"analog_{request.param}"), "--force-via", "analog",
                       "--force-file", request.param)


def test_analog_route_shares_the_clock_and_meets_the_targets(analog_session):
    """The clock is exactly shared (nothing estimated, truth's offset and drift are 0); tip,
    force and presses against the truth within the sync targets."""
    d = analog_session
    with h5py.File(d / "s" / "truth.h5") as t:
        assert t["clock/offset_s"][()] == 0 and t["clock/drift_ppm"][()] == 0
    with h5py.File(d / "synced.h5") as s:
        cal = s["calibration"].attrs
        assert cal["clock_method"] == "shared"
        assert cal["clock_offset_s"] == 0 and cal["clock_drift_ppm"] == 0
    assert "analog board" in shared_clock_checked(d)["why"]


def test_analog_route_states_against_truth(analog_session):
    check_states_against_truth(analog_session / "states.h5",
                               analog_session / "s" / "truth.h5")


def test_twin_analog_exports_name_the_gauges(analog_session):
    """The C3D cuts the six gauge labels to a repeated 'Nano17' (as real exports do); the names
    come from ANALOG:DESCRIPTIONS and match the QTM analog export's CHANNEL_NAMES."""
    s = analog_session / "s"
    c3d, tsv = read_analog(s / "indentation.c3d"), read_analog(s / "indentation_a.tsv")
    assert c3d.labels[:6] == ["Nano17"] * 6 and c3d.labels[6] == "Sync"
    assert c3d.names == tsv.names == [f"Nano17 G{k}" for k in range(6)] + ["Sync"]
    assert c3d.scales[0] == pytest.approx(10 / 32768) and c3d.point_rate_hz == 500
    np.testing.assert_allclose(c3d.values, tsv.values, atol=5e-7)     # float32 vs 6 decimals


def _toml(folder: Path, old: str, new: str) -> None:
    toml = folder / "session.toml"
    assert old in toml.read_text()
    toml.write_text(toml.read_text().replace(old, new))


def _missing_channel(folder: Path) -> str:
    _toml(folder, '"Nano17 G5"', '"Nano17 G6"')
    return "channel 'Nano17 G6' (force.channels in session.toml) is not in the file"


def _zero_scale(folder: Path) -> str:
    _toml(folder, 'file = "indentation_a.tsv"', 'file = "indentation.c3d"')
    data = bytearray((folder / "indentation.c3d").read_bytes())
    set_parameter(data, "ANALOG", "SCALE", 0.0, index=2)
    (folder / "indentation.c3d").write_bytes(bytes(data))
    return "indentation.c3d: ANALOG:SCALE of analog channel 3 is 0, not a scale factor"


def _missing_scale(folder: Path) -> str:
    _toml(folder, 'file = "indentation_a.tsv"', 'file = "indentation.c3d"')
    data = bytearray((folder / "indentation.c3d").read_bytes())
    rename_parameter(data, "ANALOG", "SCALE", "SCALX")
    (folder / "indentation.c3d").write_bytes(bytes(data))
    return "indentation.c3d: ANALOG:USED says 7 analog channels but the parameter ANALOG:SCALE"


def _rate_not_a_multiple(folder: Path) -> str:
    """The export says 1250 Hz (2.5 samples per 500 Hz frame); session.toml agrees."""
    path = folder / "indentation_a.tsv"
    text = path.read_bytes().decode()
    rows = text.split("\r\n")
    for i, row in enumerate(rows):
        cells = row.split("\t")
        if cells[0] == "CHANNEL_FREQUENCIES":
            rows[i] = "\t".join([cells[0]] + ["1250"] * (len(cells) - 1))
        elif cells[0].isdigit():                             # TIME at 1250 Hz
            cells[1] = f"{(int(cells[0]) - 1) / 1250:.5f}"
            rows[i] = "\t".join(cells)
    path.write_bytes("\r\n".join(rows).encode())
    _toml(folder, "rate_hz = 1000.0", "rate_hz = 1250.0")
    return "indentation_a.tsv: analog rate 1250 Hz is not a whole multiple of the point rate 500"


def _rate_disagrees(folder: Path) -> str:
    _toml(folder, "rate_hz = 1000.0", "rate_hz = 2000.0")
    return "session.toml says the analog rate is 2000 Hz but the file says 1000 Hz"


def _other_capture(folder: Path) -> str:
    """The analog export of a shorter capture: its last 1000 samples (1 s) gone."""
    path = folder / "indentation_a.tsv"
    rows = path.read_bytes().decode().split("\r\n")
    rows = [r for r in rows if r][:-1000]
    n = sum(r.split("\t")[0].isdigit() for r in rows)
    rows = [("\t".join(["CHANNEL_SAMPLE_COUNTS"] + [str(n)] * (r.count("\t")))
             if r.startswith("CHANNEL_SAMPLE_COUNTS") else r) for r in rows]
    path.write_bytes(("\r\n".join(rows) + "\r\n").encode())
    return "indentation_a.tsv: the analog channels span 8.986 s but the mocap export"


def _numbers_for_a_log(folder: Path) -> str:
    """In a force log, channel numbers count the columns that are not time: one beyond them
    is refused, naming the range."""
    _toml(folder, 'file = "indentation_a.tsv"', 'file = "log.csv"')
    text = (folder / "session.toml").read_text()
    line = next(x for x in text.splitlines() if x.startswith("channels = ["))
    _toml(folder, line, "channels = [1, 2, 3, 4, 5, 7]")
    (folder / "log.csv").write_text("time,a,b,c,d,e,f\n0,1,2,3,4,5,6\n0.001,1,2,3,4,5,6\n")
    return "log.csv: force.channels: channel number 7 is not in the file (channels 1 to 6"


@pytest.fixture(scope="module")
def analog_folder(tmp_path_factory) -> Path:
    return _folder(tmp_path_factory.mktemp("analog_bad") / "s")


def _folder(out: Path) -> Path:
    res = _cli("synth", out, "--seed", "5", "--locations", "1", "--repeats", "1",
               "--force-via", "analog", "--no-rrd")
    assert res.exit_code == 0, res.output
    return out


@pytest.mark.parametrize("spoil", [_missing_channel, _zero_scale, _missing_scale,
                                   _rate_not_a_multiple, _rate_disagrees, _other_capture,
                                   _numbers_for_a_log])
def test_bad_analog_input_is_one_line_exit_2_nothing_written(analog_folder, tmp_path, spoil):
    line, said, folder = ingest_spoiled(analog_folder, tmp_path, spoil)
    assert line.startswith(f"error: {folder}/") and said in line, line


def test_same_seed_same_analog_bytes_and_routes_replace_each_other(analog_folder, tmp_path):
    """The analog exports are deterministic; writing the logger route over an analog session
    (and back) leaves none of the other route's files."""
    again = _folder(tmp_path / "again")
    for name in ("indentation.c3d", "indentation_a.tsv", "session.toml"):
        assert (analog_folder / name).read_bytes() == (again / name).read_bytes(), name
    res = _cli("synth", again, "--seed", "5", "--locations", "1", "--repeats", "1", "--no-rrd")
    assert res.exit_code == 0, res.output
    names = {p.name for p in again.iterdir()}
    assert {"force.csv", "force.mat"} <= names and not names & {"indentation.c3d",
                                                               "indentation_a.tsv"}
    _folder(again)
    names = {p.name for p in again.iterdir()}
    assert {"indentation.c3d", "indentation_a.tsv"} <= names
    assert not names & {"force.csv", "force.mat"}

"""Headers that cannot be right are refused with one line naming the file, the key and the line:
no marker's data is dropped or shifted without a word (QTM TSV 3D and 6D, C3D, QTM MAT).

Each bad file is a real export (shared/real_samples) with one header value changed, or a small
file written by hand; the real exports themselves must still be read.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from pathlib import Path

import ezc3d
import h5py
import numpy as np
import pytest
import scipy.io
from helpers.c3d_bytes import c3d_parameter
from helpers.spoiled_session import ingest_spoiled

from core.errors import BadInput
from core.series import MarkerSeries
from ingest.c3d import read_c3d
from ingest.qtm_3d import read_qtm_3d
from ingest.qtm_mat import read_qtm_mat, write_mat73, write_qtm_mat
from ingest.qtm_motion import read_qtm_tsv

pytestmark = pytest.mark.usefixtures("real_samples")

QTM2026 = "qtm2026_3d_15markers_100hz.tsv"      # Frame/Time column line, TRAJECTORY_TYPES
QTM2010 = "qtm2010_3d_noheader_nan_gaps.tsv"    # no column line, rows end in a tab
QTM6D = "qtm2010_6d_3bodies.tsv"                # one label line for all bodies
C3D = "c3d/qualisys_55markers_200hz.c3d"

Edit = Callable[[list[str]], list[str]]


# ---------------------------------------------------------------------------- editing helpers


def _set(key: str, *values: str) -> Edit:
    """Give header ``key`` these values (no values: ``KEY`` and a tab)."""
    def edit(lines: list[str]) -> list[str]:
        i = next(k for k, line in enumerate(lines) if line.split("\t")[0] == key)
        return lines[:i] + ["\t".join([key, *values])] + lines[i + 1:]
    return edit


def _sub(start: str, old: str, new: str) -> Edit:
    """Replace ``old`` by ``new`` in the first line starting with ``start``."""
    def edit(lines: list[str]) -> list[str]:
        i = next(k for k, line in enumerate(lines) if line.startswith(start))
        assert old in lines[i], (old, lines[i][:80])
        return lines[:i] + [lines[i].replace(old, new, 1)] + lines[i + 1:]
    return edit


def _rows(change: Callable[[int, str], str], skip: int) -> Edit:
    """Apply ``change(row index, line)`` to every data row after ``skip`` header lines."""
    return lambda lines: lines[:skip] + [change(i, x) for i, x in enumerate(lines[skip:])]


def _both(*edits: Edit) -> Edit:
    def edit(lines: list[str]) -> list[str]:
        for e in edits:
            lines = e(lines)
        return lines
    return edit


def _lines(real_samples: Path, name: str) -> list[str]:
    return (real_samples / "qtm" / name).read_text().splitlines()


def _edited(real_samples: Path, tmp_path: Path, name: str, edit: Edit) -> Path:
    out = tmp_path / f"edited_{name}"
    out.write_text("\r\n".join(edit(_lines(real_samples, name))) + "\r\n", newline="")
    return out


def _line_of(real_samples: Path, name: str, start: str) -> str:
    """``line N`` of the first line of the real file starting with ``start``."""
    lines = _lines(real_samples, name)
    return f"line {next(k for k, x in enumerate(lines) if x.startswith(start)) + 1}"


def _refused(path: Path, read: Callable[[Path], object], *words: str) -> BadInput:
    with pytest.raises(BadInput) as err:
        read(path)
    line = err.value.line()
    assert line.startswith(f"{path}:") and "\n" not in line
    for w in words:
        assert w in line, (w, line)
    return err.value


# ---------------------------------------------------------------------------- real exports


def test_the_real_exports_are_still_read(real_samples, tmp_path):
    new = read_qtm_3d(real_samples / "qtm" / QTM2026)
    assert (new.frames, new.rate_hz, len(new.labels)) == (2000, 100.0, 15)
    old = read_qtm_3d(real_samples / "qtm" / QTM2010)
    assert (old.frames, old.rate_hz, old.labels[-1]) == (904, 256.0, "Lower Leg IMU - 3")
    bodies = read_qtm_tsv(real_samples / "qtm" / QTM6D)
    assert bodies.bodies == ["Upper Leg IMU", "Foot IMU", "Lower Leg IMU"]
    c3d = read_c3d(real_samples / C3D)
    assert (c3d.frames, c3d.rate_hz, len(c3d.labels), len(c3d.events)) == (340, 200.0, 55, 7)
    for version in ("7", "7.3"):                  # a QTM MAT export of the real markers
        mat = tmp_path / f"real_{version.replace('.', '')}.mat"
        write_qtm_mat(mat, c3d, version=version)
        back = read_qtm_mat(mat)
        assert back.labels == c3d.labels and back.frames == 340 and back.rate_hz == 200.0


# ---------------------------------------------------------------------------- QTM TSV 3D

# (real file, edit, the key line whose number the message gives, words the message holds)
TSV_CASES = {
    "frames not a count": (QTM2026, _set("NO_OF_FRAMES", "2k"), "NO_OF_FRAMES",
                           ["NO_OF_FRAMES '2k' is not a count"]),
    "frames not whole": (QTM2026, _set("NO_OF_FRAMES", "2000.5"), "NO_OF_FRAMES",
                         ["NO_OF_FRAMES '2000.5'"]),
    "frames negative": (QTM2010, _set("NO_OF_FRAMES", "-904"), "NO_OF_FRAMES",
                        ["NO_OF_FRAMES '-904'"]),
    "cameras": (QTM2026, _set("NO_OF_CAMERAS", "many"), "NO_OF_CAMERAS",
                ["NO_OF_CAMERAS 'many' is not a count"]),
    "markers not a count": (QTM2026, _set("NO_OF_MARKERS", "fifteen"), "NO_OF_MARKERS",
                            ["NO_OF_MARKERS 'fifteen'"]),
    "markers fewer than names": (QTM2026, _set("NO_OF_MARKERS", "14"), "NO_OF_MARKERS",
                                 ["NO_OF_MARKERS is 14 but MARKER_NAMES lists 15"]),
    "markers more than names": (QTM2010, _set("NO_OF_MARKERS", "15"), "NO_OF_MARKERS",
                                ["NO_OF_MARKERS is 15 but MARKER_NAMES lists 14"]),
    "frequency text": (QTM2026, _set("FREQUENCY", "abc"), "FREQUENCY",
                       ["FREQUENCY 'abc' is not a frame rate"]),
    "frequency zero": (QTM2026, _set("FREQUENCY", "0"), "FREQUENCY", ["FREQUENCY '0'"]),
    "frequency negative": (QTM2010, _set("FREQUENCY", "-256"), "FREQUENCY",
                           ["FREQUENCY '-256'"]),
    "frequency nan": (QTM2026, _set("FREQUENCY", "NaN"), "FREQUENCY", ["FREQUENCY 'NaN'"]),
    "frequency empty": (QTM2026, _set("FREQUENCY"), "FREQUENCY",
                        ["FREQUENCY must hold one value, found no value"]),
    "frequency twice": (QTM2026, _set("FREQUENCY", "100", "200"), "FREQUENCY",
                        ["FREQUENCY must hold one value, found 2 values"]),
    "frequency against time": (QTM2026, _set("FREQUENCY", "500"), "FREQUENCY",
                               ["FREQUENCY says 500 Hz but the Time column runs at 100 Hz"]),
    "analog count": (QTM2026, _set("NO_OF_ANALOG", "none"), "NO_OF_ANALOG",
                     ["NO_OF_ANALOG 'none' is not a count"]),
    "analog rate": (QTM2010, _set("ANALOG_FREQUENCY", "fast"), "ANALOG_FREQUENCY",
                    ["ANALOG_FREQUENCY 'fast' is not a sample rate"]),
    "analog channels without rate": (QTM2026, _set("NO_OF_ANALOG", "4"), "ANALOG_FREQUENCY",
                                     ["ANALOG_FREQUENCY is 0 but NO_OF_ANALOG says 4"]),
    "time stamp": (QTM2026, _set("TIME_STAMP", "yesterday"), "TIME_STAMP",
                   ["TIME_STAMP 'yesterday' is not a date and time"]),
    "time stamp seconds": (QTM2010, _set("TIME_STAMP", "2010-10-13, 17:05:42", "soon"),
                           "TIME_STAMP", ["TIME_STAMP seconds 'soon' is not a number"]),
    "data included": (QTM2026, _set("DATA_INCLUDED", "6D"), "DATA_INCLUDED",
                      ["DATA_INCLUDED is 6D but the header lists MARKER_NAMES"]),
    "duplicate name": (QTM2026, _sub("MARKER_NAMES", "\tNew 0002\t", "\tNew 0000\t"),
                       "MARKER_NAMES", ["duplicate name(s) in MARKER_NAMES: New 0000"]),
    "empty name": (QTM2010, _sub("MARKER_NAMES", "\tShin\t", "\t\t"), "MARKER_NAMES",
                   ["MARKER_NAMES has an empty name (name 4)"]),
    "trajectory types short": (QTM2026, _sub("TRAJECTORY_TYPES", "\tMeasured", ""),
                               "TRAJECTORY_TYPES", ["TRAJECTORY_TYPES has 14 entries for 15"]),
    "trajectory types empty": (QTM2026, _sub("TRAJECTORY_TYPES", "Measured\tMeasured",
                                             "Measured\t"), "TRAJECTORY_TYPES",
                               ["TRAJECTORY_TYPES has an empty entry"]),
    "event frame text": (QTM2026, _sub("DATA_INCLUDED", "3D", "3D\r\nEVENT\tTrigger\tten\t0.09"),
                         "EVENT", ["EVENT line must be: EVENT <label> <frame number>"]),
    "event frame against time": (QTM2026,
                                 _sub("DATA_INCLUDED", "3D", "3D\r\nEVENT\tTrigger\t10\t5.000"),
                                 "EVENT", ["EVENT 'Trigger' says frame 10 and 5 s, but frame 10 "
                                           "is at 0.090 s at FREQUENCY 100"]),
    # the column line names a marker MARKER_NAMES does not list instead of one it does
    "column of another marker": (QTM2026, _sub("Frame", "New 0002 X\tNew 0002 Y\tNew 0002 Z",
                                               "Foo X\tFoo Y\tFoo Z"), "Frame",
                                 ["column line names marker 'Foo' ('Foo X')", "(column 6)"]),
    # MARKER_NAMES lists one marker fewer than the column line and the data hold
    "column of an unlisted marker": (
        QTM2026, _both(_set("NO_OF_MARKERS", "14"), _sub("MARKER_NAMES", "\tNew 0015", ""),
                       _sub("TRAJECTORY_TYPES", "\tMeasured", "")), "Frame",
        ["column line names marker 'New 0015' ('New 0015 X'), which MARKER_NAMES does not "
         "list (column 45)"]),
    "columns in another order": (
        QTM2026, _sub("Frame", "New 0000 X\tNew 0000 Y\tNew 0000 Z\tNew 0002 X\tNew 0002 Y\t"
                      "New 0002 Z", "New 0002 X\tNew 0002 Y\tNew 0002 Z\tNew 0000 X\t"
                      "New 0000 Y\tNew 0000 Z"), "Frame",
        ["column line has marker 'New 0002' where MARKER_NAMES has 'New 0000'", "another order"]),
    "column twice": (QTM2026, _sub("Frame", "New 0003 Y", "New 0003 X"), "Frame",
                     ["column line names 'New 0003 X' twice (column 10)"]),
    "column of no marker": (QTM2026, _both(_sub("Frame", "Time\t", "Time\tSpeed\t"),
                                           _rows(lambda i, x: x.replace("\t", "\t7\t", 2)
                                                 .replace("\t7\t", "\t", 1), 12)),
                            "Frame", ["column line names 'Speed', which is neither Frame, Time "
                                      "nor a column of a MARKER_NAMES marker (column 3)"]),
    "row wider than the column line": (QTM2026, _rows(lambda i, x: x + "\t1.0\t2.0\t3.0", 12),
                                       "1\t0.00000", ["row has 50 fields but the column line "
                                                      "names 47"]),
    "rows wider than the names, no column line": (
        QTM2010, _rows(lambda i, x: x + "\t1\t2\t3", 10), "-853.445",
        ["row has 45 fields; 14 markers need 42"]),
    "names fewer than the data, no column line": (
        QTM2010, _both(_set("NO_OF_MARKERS", "13"), _sub("MARKER_NAMES", "\tLower Leg IMU - 3",
                                                         "")), "-853.445",
        ["13 markers need 39"]),
    # two values before the markers that are no Frame number: not Frame and Time
    "two extra values that are no frame and time": (
        QTM2010, _rows(lambda i, x: f"{i}.5\t{i / 256:.5f}\t{x}", 10), "-853.445",
        ["row has 44 fields; 14 markers need 42 (or 44 with Frame and Time), but '0.5' "
         "'0.00000' are no frame number and time"]),
    "fewer rows than NO_OF_FRAMES": (QTM2026, _set("NO_OF_FRAMES", "2001"), None,
                                     ["truncated: NO_OF_FRAMES says 2001 but the file has "
                                      "2000 data rows"]),
    "more rows than NO_OF_FRAMES": (QTM2010, _set("NO_OF_FRAMES", "903"), None,
                                    ["NO_OF_FRAMES says 903 but the file has"]),
}


@pytest.mark.parametrize("case", list(TSV_CASES))
def test_a_3d_header_that_cannot_be_right_is_refused(real_samples, tmp_path, case):
    name, edit, key_line, words = TSV_CASES[case]
    path = _edited(real_samples, tmp_path, name, edit)
    err = _refused(path, read_qtm_tsv, *words)
    if key_line == "EVENT":
        assert err.where == "line 10"             # inserted after DATA_INCLUDED, line 9
    elif key_line is not None:
        assert err.where == _line_of(real_samples, name, key_line)


def test_harmless_edits_still_read(real_samples, tmp_path):
    """The editing itself does not spoil a file: a value QTM could write reads, so each
    refusal above is the changed value's doing."""
    for name, edit in [(QTM2026, _set("NO_OF_CAMERAS", "12")),
                       (QTM2026, _sub("DATA_INCLUDED", "3D", "3D\r\nEVENT\tTrigger\t10\t0.091")),
                       (QTM2010, _set("TIME_STAMP", "2010-10-13 17:05:42")),
                       (QTM2026, _set("NO_OF_MARKERS", "015")),
                       (QTM2010, _set("FREQUENCY", "256.0"))]:
        s = read_qtm_3d(_edited(real_samples, tmp_path, name, edit))
        assert s.frames == len(s.time_ns) > 900


# ---------------------------------------------------------------------------- QTM TSV 6D

BODY_CASES = {
    "bodies not a count": (_set("NO_OF_BODIES", "three"), "NO_OF_BODIES",
                           ["NO_OF_BODIES 'three' is not a count"]),
    "bodies more than names": (_set("NO_OF_BODIES", "4"), "NO_OF_BODIES",
                               ["NO_OF_BODIES is 4 but BODY_NAMES lists 3"]),
    "data included": (_set("DATA_INCLUDED", "3D"), "DATA_INCLUDED",
                      ["DATA_INCLUDED is 3D but the header lists BODY_NAMES (a 6D export)"]),
    "duplicate body": (_sub("BODY_NAMES", "Lower Leg IMU", "Foot IMU"), "BODY_NAMES",
                       ["duplicate name(s) in BODY_NAMES: Foot IMU"]),
    "frequency": (_set("FREQUENCY", "256 Hz"), "FREQUENCY", ["FREQUENCY '256 Hz'"]),
    "names fewer than the data": (_both(_set("NO_OF_BODIES", "2"),
                                        _sub("BODY_NAMES", "\tLower Leg IMU", "")),
                                  "-761.16144", ["does not fit 2 bodies"]),
}


@pytest.mark.parametrize("case", list(BODY_CASES))
def test_a_6d_header_that_cannot_be_right_is_refused(real_samples, tmp_path, case):
    edit, key_line, words = BODY_CASES[case]
    path = _edited(real_samples, tmp_path, QTM6D, edit)
    err = _refused(path, read_qtm_tsv, *words)
    assert err.where == _line_of(real_samples, QTM6D, key_line)


_PER_BODY = ["X", "Y", "Z", "Roll", "Pitch", "Yaw", "Residual", *(f"Rot[{k}]" for k in range(9))]


def _6d_file(tmp_path: Path, names: list[str], column_bodies: list[str],
             extra_columns: int = 0) -> Path:
    """A QTM 2021-style 6D export: ``names`` in BODY_NAMES, a column line for
    ``column_bodies`` (the body's name on its X label, as QTM writes it), two frames."""
    head = ["NO_OF_FRAMES\t2", "NO_OF_CAMERAS\t5", f"NO_OF_BODIES\t{len(names)}",
            "FREQUENCY\t100", "NO_OF_ANALOG\t0", "ANALOG_FREQUENCY\t0", "DESCRIPTION\t--",
            "TIME_STAMP\t2026-11-21, 09:00:00.000\t100.0", "DATA_INCLUDED\t6D",
            "BODY_NAMES\t" + "\t".join(names)]
    cols = ["Frame", "Time"] + [f"{b} {p}" if p == "X" else p for b in column_bodies
                                for p in _PER_BODY]
    body = ["10", "20", "30", "0", "0", "0", "0.5", "1", "0", "0", "0", "1", "0", "0", "0", "1"]
    rows = ["\t".join([str(i + 1), f"{i / 100:.5f}", *body * len(column_bodies),
                       *["0"] * extra_columns]) for i in range(2)]
    p = tmp_path / "bodies_6d.tsv"
    p.write_text("\r\n".join([*head, "\t".join(cols) + "\t", *rows]) + "\r\n", newline="")
    return p


def test_a_6d_column_line_as_qtm_writes_it_reads(tmp_path):
    s = read_qtm_tsv(_6d_file(tmp_path, ["Indenter", "Plate"], ["Indenter", "Plate"]))
    assert s.bodies == ["Indenter", "Plate"] and s.frames == 2
    assert s.positions[1, 1] == pytest.approx([0.01, 0.02, 0.03])


@pytest.mark.parametrize("columns, extra, words", [
    (["Plate", "Indenter"], 0, ["names body 'Plate' in column 3 ('Plate X'), but in "
                                "BODY_NAMES body 1 is 'Indenter'"]),
    (["Indenter", "Probe"], 0, ["names body 'Probe' in column 19", "body 2 is 'Plate'"]),
    (["Indenter", "Plate", "Probe"], 0, ["does not fit 2 bodies"]),
    (["Indenter", "Plate"], 3, ["does not fit 2 bodies"]),
    (["Indenter", "Plate"], 1, ["does not fit 2 bodies"]),      # one value after the bodies
])
def test_a_6d_column_line_that_contradicts_body_names(tmp_path, columns, extra, words):
    path = _6d_file(tmp_path, ["Indenter", "Plate"], columns, extra)
    _refused(path, read_qtm_tsv, *words)


# ---------------------------------------------------------------------------- C3D


def _patched_c3d(real_samples: Path, tmp_path: Path, changes: dict[str, float],
                 points_in_header: int | None = None) -> Path:
    data = bytearray((real_samples / C3D).read_bytes())
    for key, value in changes.items():
        offset, kind = c3d_parameter(bytes(data), *key.split(":"))
        struct.pack_into("<f" if kind == 4 else "<h", data, offset, value)
    if points_in_header is not None:
        struct.pack_into("<H", data, 2, points_in_header)              # header word 2
    out = tmp_path / "patched.c3d"
    out.write_bytes(bytes(data))
    return out


@pytest.mark.parametrize("changes, points, words", [
    ({"POINT:RATE": 100.0}, None, ["POINT:RATE says 100 Hz but the header says 200 Hz"]),
    ({"POINT:USED": 54}, None, ["POINT:USED says 54 points but the header says 55 points"]),
    ({"POINT:FRAMES": 341}, None, ["POINT:FRAMES says 341 frames but the header says 340"]),
    ({"POINT:DATA_START": 30}, None, ["POINT:DATA_START says data block 30 but the header "
                                      "says data block 29"]),
    ({"POINT:SCALE": 0.0}, None, ["POINT:SCALE 0 is not a scale factor"]),
    # header and POINT:USED agree on 54 points, but POINT:LABELS names 55
    ({"POINT:USED": 54}, 54, ["POINT:LABELS names 55 points but POINT:USED and the data hold "
                              "54 (no data for R_SAJ)"]),
    ({"EVENT:USED": 6}, None, ["EVENT:TIMES has shape (2, 7) for 7 EVENT:LABELS, EVENT:USED "
                               "says 6"]),
])
def test_a_c3d_whose_parameters_contradict_its_header(real_samples, tmp_path, changes, points,
                                                        words):
    path = _patched_c3d(real_samples, tmp_path, changes, points)
    _refused(path, read_c3d, *words)


def test_the_c3d_patch_itself_leaves_a_readable_file(real_samples, tmp_path):
    """Writing the values the file already has changes nothing: the refusals above are the
    changed values' doing, not the patching's."""
    path = _patched_c3d(real_samples, tmp_path, {"POINT:RATE": 200.0, "POINT:USED": 55,
                                                 "EVENT:USED": 7}, 55)
    assert path.read_bytes() == (real_samples / C3D).read_bytes()
    assert read_c3d(path).frames == 340


# ---------------------------------------------------------------------------- QTM MAT


def _mat_struct(**fields: object) -> dict:
    """A QTM MAT struct of two markers over four frames, with ``fields`` replaced."""
    data = np.zeros((2, 4, 4))
    data[:, :3] = 1.0
    labeled = {"Count": fields.pop("Count", 2.0), "Labels": ["A", "B"], "Data": data}
    return {"File": "t.mat", "StartFrame": 1.0, "Frames": 4.0, "FrameRate": 100.0,
            "Timestamp": "2026-11-21, 09:00:00", **fields,
            "Trajectories": {"Labeled": labeled}}


def _write_mat(path: Path, struct: dict, version: str) -> Path:
    if version == "7.3":
        write_mat73(path, {"t": struct})
        return path
    labels = np.empty((1, 2), dtype=object)
    labels[0, :] = struct["Trajectories"]["Labeled"]["Labels"]
    struct["Trajectories"]["Labeled"]["Labels"] = labels
    scipy.io.savemat(path, {"t": struct}, oned_as="row")
    return path


MAT_CASES = {
    "count against data": ({"Count": 3.0}, "t.Trajectories.Labeled.Count is 3 but Data holds 2"),
    "count not whole": ({"Count": 2.5}, "t.Trajectories.Labeled.Count 2.5 is not a count"),
    "frames against data": ({"Frames": 5.0}, "t.Frames is 5 but Data has 4 frames"),
    "frames not whole": ({"Frames": 4.5}, "t.Frames 4.5 is not a count"),
    "frames text": ({"Frames": "four"}, "t.Frames is not a number ('four')"),
    "rate text": ({"FrameRate": "fast"}, "t.FrameRate is not a number ('fast')"),
    "rate zero": ({"FrameRate": 0.0}, "t.FrameRate 0 is not a frame rate"),
    "rate two values": ({"FrameRate": [100.0, 200.0]}, "t.FrameRate is not a number"),
    "start frame": ({"StartFrame": -1.0}, "t.StartFrame -1 is not a count"),
}


@pytest.mark.parametrize("version", ["7", "7.3"])
@pytest.mark.parametrize("case", list(MAT_CASES))
def test_a_qtm_mat_whose_fields_contradict_the_data(tmp_path, version, case):
    fields, words = MAT_CASES[case]
    path = _write_mat(tmp_path / "t.mat", _mat_struct(**fields), version)
    _refused(path, read_qtm_mat, words)


@pytest.mark.parametrize("version", ["7", "7.3"])
def test_a_qtm_mat_that_agrees_with_itself_reads(tmp_path, version):
    s = read_qtm_mat(_write_mat(tmp_path / "t.mat", _mat_struct(), version))
    assert s.labels == ["A", "B"] and s.frames == 4 and s.rate_hz == 100.0
    assert s.meta["start_frame"] == 1


# ---------------------------------------------------------------------------- the CLI


@pytest.fixture(scope="module")
def twin_session(tmp_path_factory) -> Path:
    """A small phantom-twin session folder (QTM 3D and 6D exports, force log, session.toml)."""
    twin = pytest.importorskip("sim.twin.synth_stage")
    return twin.run_synth(None, tmp_path_factory.mktemp("twin") / "session",
                          twin.SynthParams(seed=2, locations=1, repeats=1))


def _spoil_tsv(folder: Path) -> str:
    p = folder / "indentation.tsv"
    p.write_bytes(p.read_bytes().replace(b"FREQUENCY\t500\r\n", b"FREQUENCY\t250\r\n", 1))
    return "indentation.tsv:line 4: FREQUENCY says 250 Hz but the Time column runs at 500 Hz"


def _spoil_6d(folder: Path) -> str:
    p = folder / "indentation_6D.tsv"
    p.write_bytes(p.read_bytes().replace(b"\tTime\tIndenter X\t", b"\tTime\tPlate X\t", 1))
    return "indentation_6D.tsv:line "


def _mocap_as(folder: Path, name: str) -> MarkerSeries:
    """Point session.toml at ``name`` instead of the 3D TSV; return the markers to write."""
    toml = folder / "session.toml"
    toml.write_text(toml.read_text().replace('file = "indentation.tsv"', f'file = "{name}"'))
    return read_qtm_3d(folder / "indentation.tsv")


def _spoil_mat(folder: Path) -> str:
    markers = _mocap_as(folder, "indentation.mat")
    write_qtm_mat(folder / "indentation.mat", markers, version="7.3")
    with h5py.File(folder / "indentation.mat", "r+") as f:
        f["indentation/Trajectories/Labeled/Count"][...] = len(markers.labels) + 1
    return "indentation.mat: indentation.Trajectories.Labeled.Count is 30 but Data holds 29"


def _spoil_c3d(folder: Path) -> str:
    markers = _mocap_as(folder, "indentation.c3d")
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [markers.rate_hz]
    c["parameters"]["POINT"]["LABELS"]["value"] = markers.labels
    c["parameters"]["POINT"]["UNITS"]["value"] = ["m"]
    pts = np.ones((4, len(markers.labels), markers.frames))
    pts[:3] = np.nan_to_num(markers.positions.transpose(2, 1, 0))
    c["data"]["points"] = pts
    c.write(str(folder / "indentation.c3d"))
    data = bytearray((folder / "indentation.c3d").read_bytes())
    offset, _ = c3d_parameter(bytes(data), "POINT", "RATE")
    struct.pack_into("<f", data, offset, 250.0)
    (folder / "indentation.c3d").write_bytes(bytes(data))
    return "indentation.c3d: POINT:RATE says 250 Hz but the header says 500 Hz"


@pytest.mark.parametrize("spoil", [_spoil_tsv, _spoil_6d, _spoil_mat, _spoil_c3d],
                         ids=["tsv_3d", "tsv_6d", "qtm_mat", "c3d"])
def test_ingest_says_one_line_exits_2_and_writes_nothing(twin_session, tmp_path, spoil):
    line, said, folder = ingest_spoiled(twin_session, tmp_path, spoil)
    assert line.startswith(f"error: {folder}/{said}"), line

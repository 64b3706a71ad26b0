"""QTM TSV 3D/6D reader: real exports checked against their raw text, every layout variant,
and one test per kind of bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.errors import BadInput
from core.series import BodySeries, MarkerSeries
from ingest.qtm_tsv import parse_qtm_header, read_qtm_3d, read_qtm_6d, read_qtm_tsv

pytestmark = pytest.mark.usefixtures("real_samples")

QTM = Path(__file__).resolve().parents[2] / "shared" / "real_samples" / "qtm"
OLD_3D = QTM / "qtm2010_3d_noheader_nan_gaps.tsv"
NEW_3D = QTM / "qtm2026_3d_15markers_100hz.tsv"
OLD_6D = QTM / "qtm2010_6d_3bodies.tsv"


def _raw_rows(path: Path, skip: int) -> list[list[str]]:
    """The data rows of a real file, split by hand (an independent reading)."""
    lines = path.read_text().splitlines()[skip:]
    return [line.split("\t") for line in lines if line.strip()]


# ---------------------------------------------------------------------------- real files


def test_old_3d_export_without_frame_time_columns():
    s = read_qtm_3d(OLD_3D)
    assert isinstance(s, MarkerSeries)
    assert s.frames == 904 and s.rate_hz == 256.0 and len(s.labels) == 14
    assert s.labels[2] == "Knee Hinge" and s.labels[5] == "Upper Leg IMU - 1"
    rows = _raw_rows(OLD_3D, 10)
    assert len(rows) == 904
    nan_triples = sum(r[3 * m:3 * m + 3] == ["NaN"] * 3 for r in rows for m in range(14))
    assert nan_triples == 7 == s.missing_samples()
    assert s.positions[0, 0, 0] == pytest.approx(float(rows[0][0]) / 1000)     # -853.445 mm
    assert s.positions[-1, 13, 2] == pytest.approx(float(rows[-1][41]) / 1000)
    assert s.time_ns[1] == 3_906_250 and s.time_ns[-1] == round(903 / 256 * 1e9)
    assert s.positions.shape == (904, 14, 3)


def test_new_3d_export_with_column_line_and_time():
    s = read_qtm_3d(NEW_3D)
    assert s.frames == 2000 and s.rate_hz == 100.0
    assert s.labels[:3] == ["New 0000", "New 0002", "New 0003"] and len(s.labels) == 15
    rows = _raw_rows(NEW_3D, 12)
    assert s.positions[0, 0] == pytest.approx(np.array(rows[0][2:5], float) / 1000)
    assert s.positions[1999, 14] == pytest.approx(np.array(rows[1999][44:47], float) / 1000)
    assert s.time_ns[0] == 0 and s.time_ns[-1] == 19_990_000_000
    gaps = sum(all(float(v) == 0 for v in r[2 + 3 * m:5 + 3 * m]) for r in rows for m in range(15))
    assert s.missing_samples() == gaps
    assert s.meta["trajectory_types"] == ["Measured"] * 15


def test_old_6d_export_bodies_rotations_and_lost_frames():
    s = read_qtm_6d(OLD_6D)
    assert isinstance(s, BodySeries)
    assert s.bodies == ["Upper Leg IMU", "Foot IMU", "Lower Leg IMU"] and s.frames == 904
    rows = _raw_rows(OLD_6D, 11)
    lost = sum(r[17 * b + 6] == "-1.00000" for r in rows for b in range(3))
    assert lost == 7 == s.missing_samples()
    assert np.isnan(s.rotations[np.isnan(s.residuals)]).all()
    first = np.array(rows[0][17:33], float)                               # second body, row 0
    assert s.positions[0, 1] == pytest.approx(first[:3] / 1000)
    assert s.residuals[0, 1] == pytest.approx(first[6] / 1000)
    # Rot[0..8] is column-major: check against the file's own Euler angles (label row
    # "Yaw Pitch Roll"), which give R = Rz(yaw) Ry(pitch) Rx(roll) for this export
    yaw, pitch, roll = np.radians(first[3:6])
    c, s_ = np.cos, np.sin
    rz = np.array([[c(yaw), -s_(yaw), 0], [s_(yaw), c(yaw), 0], [0, 0, 1]])
    ry = np.array([[c(pitch), 0, s_(pitch)], [0, 1, 0], [-s_(pitch), 0, c(pitch)]])
    rx = np.array([[1, 0, 0], [0, c(roll), -s_(roll)], [0, s_(roll), c(roll)]])
    assert np.abs(s.rotations[0, 1] - rz @ ry @ rx).max() < 1e-4
    ok = ~np.isnan(s.residuals)
    r = s.rotations[ok]
    assert np.abs(r @ r.transpose(0, 2, 1) - np.eye(3)).max() < 1e-3


def test_read_qtm_tsv_dispatches_on_header_keys():
    assert isinstance(read_qtm_tsv(NEW_3D), MarkerSeries)
    assert isinstance(read_qtm_tsv(OLD_6D), BodySeries)


def test_parse_qtm_header():
    h = parse_qtm_header(NEW_3D)
    assert h["NO_OF_FRAMES"] == "2000" and h["FREQUENCY"] == "100"
    assert h["TIME_STAMP"] == ["2026-01-19, 10:19:43.755", "2063631.96175450"]
    assert h["MARKER_NAMES"][0] == "New 0000" and len(h["MARKER_NAMES"]) == 15
    assert parse_qtm_header(OLD_6D)["BODY_NAMES"] == ["Upper Leg IMU", "Foot IMU",
                                                      "Lower Leg IMU"]


# ---------------------------------------------------------------------------- variants


def _header(names: list[str], frames: int, rate: float = 500, key: str = "MARKER_NAMES",
            extra: tuple[str, ...] = ()) -> list[str]:
    count = "NO_OF_MARKERS" if key == "MARKER_NAMES" else "NO_OF_BODIES"
    return [f"NO_OF_FRAMES\t{frames}", "NO_OF_CAMERAS\t8", f"{count}\t{len(names)}",
            f"FREQUENCY\t{rate:g}", "NO_OF_ANALOG\t0", "ANALOG_FREQUENCY\t0", "DESCRIPTION\t--",
            "TIME_STAMP\t2026-11-21, 09:12:00",
            "DATA_INCLUDED\t" + ("3D" if key == "MARKER_NAMES" else "6D"), *extra,
            key + "\t" + "\t".join(names)]


def _write(tmp_path: Path, lines: list[str], name: str = "t.tsv", end: str = "\r\n") -> Path:
    p = tmp_path / name
    p.write_bytes((end.join(lines) + end).encode())
    return p


def test_gap_spellings_become_nan(tmp_path):
    names = ["P 1", "P-2"]
    rows = ["1\t0.000\t1.0\t2.0\t3.0\tnull\tnull\tnull",
            "2\t0.002\t\t\t\t4.0\t5.0\t6.0",
            "3\t0.004\t0.000\t0.000\t0.000\tNaN\tNaN\tNaN",
            "4\t0.006\t0.000\t7.0\t0.000\t8.0\t9.0\t10.0"]
    cols = "Frame\tTime\tP 1 X\tP 1 Y\tP 1 Z\tP-2 X\tP-2 Y\tP-2 Z"
    s = read_qtm_3d(_write(tmp_path, [*_header(names, 4), cols, *rows]))
    missing = np.isnan(s.positions).any(axis=2)
    assert missing.tolist() == [[False, True], [True, False], [True, True], [False, False]]
    assert s.positions[3, 0] == pytest.approx([0, 0.007, 0])      # one zero is a real value
    assert s.positions[0, 0] == pytest.approx([0.001, 0.002, 0.003])
    assert s.time_ns.tolist() == [0, 2_000_000, 4_000_000, 6_000_000]


def test_events_no_frame_time_trailing_tabs_and_lf(tmp_path):
    extra = ("EVENT\tTrigger\t2\t0.004", "EVENT\tStop press\t3\t0.006")
    lines = [line + "\t" for line in _header(["A", "B"], 3, 250, extra=extra)]
    rows = ["1\t2\t3\t4\t5\t6\t", "7\t8\t9\t10\t11\t12\t", "13\t14\t15\t16\t17\t18\t"]
    s = read_qtm_3d(_write(tmp_path, lines + rows, end="\n"))
    assert s.events == [("Trigger", 4_000_000), ("Stop press", 6_000_000)]
    assert s.time_ns.tolist() == [0, 4_000_000, 8_000_000] and s.rate_hz == 250
    assert s.positions[2, 1] == pytest.approx([0.016, 0.017, 0.018])
    assert parse_qtm_header(tmp_path / "t.tsv")["EVENT"][0] == ("Trigger", 2, 0.004)


def test_frame_time_columns_without_column_line_and_units_key(tmp_path):
    lines = _header(["A"], 2, 100, extra=("FILE_VERSION\t2.0.0", "MARKER_UNITS\tm"))
    s = read_qtm_3d(_write(tmp_path, [*lines, "1\t0.5\t1\t2\t3", "2\t0.51\t4\t5\t6"]))
    assert s.time_ns.tolist() == [500_000_000, 510_000_000]
    assert s.positions[1, 0] == pytest.approx([4, 5, 6])            # metres already


def test_new_6d_layout_with_frame_time_and_column_line(tmp_path):
    head = _header(["Indenter", "Plate"], 2, 500, key="BODY_NAMES")
    per = ["X", "Y", "Z", "Roll", "Pitch", "Yaw", "Residual", *(f"Rot[{k}]" for k in range(9))]
    cols = ["Frame", "Time"] + [f"{b} {p}" for b in ("Indenter", "Plate") for p in per]
    rot = [0, 1, 0, -1, 0, 0, 0, 0, 1]                   # columns e_y, -e_x, e_z
    good = ["10", "20", "30", "0", "0", "90", "0.5", *map(str, rot)]
    lost = ["0"] * 6 + ["-1"] + ["0"] * 9
    rows = ["\t".join(["1", "0.000", *good, *lost]), "\t".join(["2", "0.002", *lost, *good])]
    s = read_qtm_tsv(_write(tmp_path, [*head, "\t".join(cols), *rows]))
    assert isinstance(s, BodySeries) and s.bodies == ["Indenter", "Plate"]
    assert s.positions[0, 0] == pytest.approx([0.01, 0.02, 0.03])
    assert s.rotations[0, 0] @ np.array([1, 0, 0]) == pytest.approx([0, 1, 0])
    assert s.residuals[0, 0] == pytest.approx(0.0005)
    assert np.isnan(s.positions[0, 1]).all() and np.isnan(s.rotations[1, 0]).all()
    assert s.missing_samples() == 2 and s.time_ns.tolist() == [0, 2_000_000]


def test_empty_cells_in_first_row_are_data_not_labels(tmp_path):
    rows = ["NaN\tNaN\tNaN\t1\t2\t3", "4\t5\t6\tnull\tnull\tnull"]
    s = read_qtm_3d(_write(tmp_path, [*_header(["A", "B"], 2), *rows]))
    assert s.missing_samples() == 2 and s.frames == 2


# ---------------------------------------------------------------------------- bad input


def _bad(path: Path, *needles: str) -> BadInput:
    with pytest.raises(BadInput) as e:
        read_qtm_tsv(path)
    msg = str(e.value)
    assert str(path) in msg
    for n in needles:
        assert n in msg
    return e.value


def _good_lines(frames: int = 4, claimed: int | None = None) -> list[str]:
    cols = "Frame\tTime\tA X\tA Y\tA Z\tB X\tB Y\tB Z"
    rows = [f"{i + 1}\t{i * 0.002:.5f}\t{i}.125\t2.250\t3.375\t4.500\t5.625\t6.750"
            for i in range(frames)]
    return [*_header(["A", "B"], frames if claimed is None else claimed), cols, *rows]


def test_bad_fewer_rows_than_no_of_frames(tmp_path):
    _bad(_write(tmp_path, _good_lines(4, claimed=6)), "truncated", "NO_OF_FRAMES")


def test_bad_partial_last_row(tmp_path):
    p = _write(tmp_path, _good_lines(4))
    p.write_bytes(p.read_bytes()[:-20])
    e = _bad(p, "truncated")
    assert e.where == "line 15"


def test_bad_last_row_cut_inside_a_number(tmp_path):
    p = _write(tmp_path, _good_lines(4))
    p.write_bytes(p.read_bytes()[:-4])                      # "...6.750\r\n" -> "...6.7"
    _bad(p, "truncated", "line 15")


def test_bad_more_rows_than_no_of_frames(tmp_path):
    _bad(_write(tmp_path, _good_lines(4, claimed=3)), "NO_OF_FRAMES says 3")


def test_bad_huge_no_of_frames_is_not_allocated(tmp_path):
    _bad(_write(tmp_path, _good_lines(4, claimed=10**13)), "truncated")


def test_bad_no_of_markers_contradicts_names(tmp_path):
    lines = [line.replace("NO_OF_MARKERS\t2", "NO_OF_MARKERS\t3") for line in _good_lines()]
    _bad(_write(tmp_path, lines), "NO_OF_MARKERS is 3", "line 3")


def test_bad_names_contradict_columns(tmp_path):
    lines = _good_lines()
    lines[9] = "MARKER_NAMES\tA\tB\tC"
    lines[2] = "NO_OF_MARKERS\t3"
    _bad(_write(tmp_path, lines), "column line has no column 'C X'")
    no_column_line = [ln for ln in lines if not ln.startswith("Frame")]
    _bad(_write(tmp_path, no_column_line, "n.tsv"), "3 markers need 9", "line 11")


def test_bad_non_increasing_time(tmp_path):
    lines = _good_lines(5)
    lines[13] = lines[13].replace("\t0.00400\t", "\t0.00200\t")
    _bad(_write(tmp_path, lines), "not increasing", "line 14")


def test_bad_duplicate_marker_names(tmp_path):
    lines = _good_lines()
    lines[9] = "MARKER_NAMES\tA\tA"
    _bad(_write(tmp_path, lines), "duplicate", "A")


def test_bad_text_where_numbers_must_be(tmp_path):
    lines = _good_lines(6)
    lines[13] = lines[13].replace("5.625", "5.6x5")
    _bad(_write(tmp_path, lines), "'5.6x5'", "line 14", "not a number")


def test_bad_6d_row_that_fits_no_body_layout(tmp_path):
    head = _header(["Indenter"], 1, key="BODY_NAMES")
    _bad(_write(tmp_path, [*head, "\t".join(["1"] * 15)]), "does not fit 1 bodies")


@pytest.mark.parametrize("content", [
    b"hello world\nthis is not a mocap export\n",
    b"\x00\x01\x02binary" * 50,
    b"",
    b"NO_OF_FRAMES\t2\nDATA_INCLUDED\t2D\n1\t2\n3\t4\n",
])
def test_bad_unknown_or_unsupported_file(tmp_path, content):
    p = tmp_path / "x.tsv"
    p.write_bytes(content)
    _bad(p)


def test_bad_header_without_data(tmp_path):
    _bad(_write(tmp_path, _good_lines(4)[:11]), "truncated", "no data rows")


def test_bad_missing_file(tmp_path):
    _bad(tmp_path / "absent.tsv", "no such file")


def test_where_points_at_the_frame_time_of_the_bad_row(tmp_path):
    lines = _good_lines(5)
    lines[12] = lines[12].replace("\t0.00200\t", "\tnull\t")
    e = _bad(_write(tmp_path, lines), "Time is missing")
    assert e.where == "line 13"


def test_bad_text_in_the_first_row_without_column_line(tmp_path):
    rows = ["1\t2\t3", "4\t5\t6"]
    _bad(_write(tmp_path, [*_header(["A"], 3), "1\t2\tabc", *rows]), "'abc' is not a number",
         "line 11")


def test_no_no_of_frames_key_and_many_rows(tmp_path):
    """Without NO_OF_FRAMES the reader sizes its buffer from the data (and grows it)."""
    n = 70_000
    head = [line for line in _header(["A"], 0) if not line.startswith("NO_OF_FRAMES")]
    rows = [f"{i}.5\t1\t2" for i in range(n)]
    s = read_qtm_3d(_write(tmp_path, head + rows))
    assert s.frames == n and s.positions[-1, 0, 0] == pytest.approx((n - 1 + 0.5) / 1000)
    assert s.time_ns[-1] == round((n - 1) / 500 * 1e9)


def test_6d_frame_time_without_labels_two_bodies(tmp_path):
    body = ["1", "2", "3", "0", "0", "0", "0.4", "1", "0", "0", "0", "1", "0", "0", "0", "1"]
    rows = ["\t".join([str(i + 1), f"{i / 100:.5f}", *body, *body]) for i in range(3)]
    s = read_qtm_6d(_write(tmp_path, [*_header(["A", "B"], 3, 100, key="BODY_NAMES"), *rows]))
    assert s.time_ns.tolist() == [0, 10_000_000, 20_000_000]
    assert s.positions[2, 1] == pytest.approx([0.001, 0.002, 0.003])
    assert np.array_equal(s.rotations[0, 0], np.eye(3)) and s.missing_samples() == 0


def test_last_line_without_line_break_is_accepted_when_complete(tmp_path):
    p = _write(tmp_path, _good_lines(4))
    p.write_bytes(p.read_bytes()[:-2])                      # drop the final "\r\n"
    s = read_qtm_3d(p)
    assert s.frames == 4 and s.positions[3, 1, 2] == pytest.approx(0.00675)


def test_last_line_without_line_break_ending_in_a_gap(tmp_path):
    rows = ["1.000\t2.000\t3.000\t1.000\t2.000\t3.000", "4.000\t5.000\t6.000\tNaN\tNaN\tNaN"]
    p = _write(tmp_path, [*_header(["a", "b"], 2, 100), *rows], end="\n")
    p.write_bytes(p.read_bytes()[:-1])                      # complete, no final line break
    s = read_qtm_3d(p)
    assert s.frames == 2 and np.isnan(s.positions[1, 1]).all()


@pytest.mark.parametrize("value", ["inf", "-inf", "1e400"])
def test_bad_infinite_coordinate(tmp_path, value):
    lines = _good_lines(4)
    lines[12] = lines[12].replace("\t2.250\t", f"\t{value}\t", 1)
    _bad(_write(tmp_path, lines), "line 13", "column 4", "not a finite number")


def test_bad_time_out_of_int64_range(tmp_path):
    lines = _good_lines(2)
    lines[12] = lines[12].replace("\t0.00200\t", "\t1e300\t")
    _bad(_write(tmp_path, lines), "line 13", "1e+300 s", "int64 nanosecond range")


@pytest.mark.parametrize("rate, words", [("1e-300", "too low"), ("0", "not a frame rate"),
                                         ("1e12", "not a frame rate")])
def test_bad_frequency_of_a_file_timed_by_it(tmp_path, rate, words):
    lines = [ln.replace("FREQUENCY\t500", f"FREQUENCY\t{rate}") for ln in
             _header(["A"], 2)] + ["1\t2\t3", "4\t5\t6"]
    _bad(_write(tmp_path, lines), "FREQUENCY", words, "line 4")


def test_bad_event_time(tmp_path):
    lines = _good_lines(2)
    lines.insert(9, "EVENT\tTrigger\t1\tinf")
    _bad(_write(tmp_path, lines), "EVENT 1", "int64 nanosecond range")

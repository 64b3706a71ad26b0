"""QTM TSV 3D exports (`ingest/qtm_3d.py`): real exports checked against their raw text,
every layout variant, and the column layouts that cannot be right."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.qtm_files import (
    NEW_3D,
    OLD_3D,
    good_3d_lines,
    qtm_header,
    raw_rows,
    refused,
    write_tsv,
)

from core.series import MarkerSeries
from ingest.qtm_3d import read_qtm_3d
from ingest.qtm_scan import parse_qtm_header

pytestmark = pytest.mark.usefixtures("real_samples")


def test_old_3d_export_without_frame_time_columns():
    s = read_qtm_3d(OLD_3D)
    assert isinstance(s, MarkerSeries)
    assert s.frames == 904 and s.rate_hz == 256.0 and len(s.labels) == 14
    assert s.labels[2] == "Knee Hinge" and s.labels[5] == "Upper Leg IMU - 1"
    rows = raw_rows(OLD_3D, 10)
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
    rows = raw_rows(NEW_3D, 12)
    assert s.positions[0, 0] == pytest.approx(np.array(rows[0][2:5], float) / 1000)
    assert s.positions[1999, 14] == pytest.approx(np.array(rows[1999][44:47], float) / 1000)
    assert s.time_ns[0] == 0 and s.time_ns[-1] == 19_990_000_000
    gaps = sum(all(float(v) == 0 for v in r[2 + 3 * m:5 + 3 * m]) for r in rows for m in range(15))
    assert s.missing_samples() == gaps
    assert s.meta["trajectory_types"] == ["Measured"] * 15


def test_gap_spellings_become_nan(tmp_path):
    names = ["P 1", "P-2"]
    rows = ["1\t0.000\t1.0\t2.0\t3.0\tnull\tnull\tnull",
            "2\t0.002\t\t\t\t4.0\t5.0\t6.0",
            "3\t0.004\t0.000\t0.000\t0.000\tNaN\tNaN\tNaN",
            "4\t0.006\t0.000\t7.0\t0.000\t8.0\t9.0\t10.0"]
    cols = "Frame\tTime\tP 1 X\tP 1 Y\tP 1 Z\tP-2 X\tP-2 Y\tP-2 Z"
    s = read_qtm_3d(write_tsv(tmp_path, [*qtm_header(names, 4), cols, *rows]))
    missing = np.isnan(s.positions).any(axis=2)
    assert missing.tolist() == [[False, True], [True, False], [True, True], [False, False]]
    assert s.positions[3, 0] == pytest.approx([0, 0.007, 0])      # one zero is a real value
    assert s.positions[0, 0] == pytest.approx([0.001, 0.002, 0.003])
    assert s.time_ns.tolist() == [0, 2_000_000, 4_000_000, 6_000_000]


def test_events_no_frame_time_trailing_tabs_and_lf(tmp_path):
    extra = ("EVENT\tTrigger\t2\t0.004", "EVENT\tStop press\t3\t0.006")
    lines = [line + "\t" for line in qtm_header(["A", "B"], 3, 250, extra=extra)]
    rows = ["1\t2\t3\t4\t5\t6\t", "7\t8\t9\t10\t11\t12\t", "13\t14\t15\t16\t17\t18\t"]
    s = read_qtm_3d(write_tsv(tmp_path, lines + rows, end="\n"))
    assert s.events == [("Trigger", 4_000_000), ("Stop press", 6_000_000)]
    assert s.time_ns.tolist() == [0, 4_000_000, 8_000_000] and s.rate_hz == 250
    assert s.positions[2, 1] == pytest.approx([0.016, 0.017, 0.018])
    assert parse_qtm_header(tmp_path / "t.tsv")["EVENT"][0] == ("Trigger", 2, 0.004)


def test_frame_time_columns_without_column_line_and_units_key(tmp_path):
    lines = qtm_header(["A"], 2, 100, extra=("FILE_VERSION\t2.0.0", "MARKER_UNITS\tm"))
    s = read_qtm_3d(write_tsv(tmp_path, [*lines, "1\t0.5\t1\t2\t3", "2\t0.51\t4\t5\t6"]))
    assert s.time_ns.tolist() == [500_000_000, 510_000_000]
    assert s.positions[1, 0] == pytest.approx([4, 5, 6])            # metres already


def test_empty_cells_in_first_row_are_data_not_labels(tmp_path):
    rows = ["NaN\tNaN\tNaN\t1\t2\t3", "4\t5\t6\tnull\tnull\tnull"]
    s = read_qtm_3d(write_tsv(tmp_path, [*qtm_header(["A", "B"], 2), *rows]))
    assert s.missing_samples() == 2 and s.frames == 2


def test_bad_names_contradict_columns(tmp_path):
    lines = good_3d_lines()
    lines[9] = "MARKER_NAMES\tA\tB\tC"
    lines[2] = "NO_OF_MARKERS\t3"
    refused(write_tsv(tmp_path, lines), "column line has no column 'C X'")
    no_column_line = [ln for ln in lines if not ln.startswith("Frame")]
    refused(write_tsv(tmp_path, no_column_line, "n.tsv"), "3 markers need 9", "line 11")


def test_bad_text_in_the_first_row_without_column_line(tmp_path):
    rows = ["1\t2\t3", "4\t5\t6"]
    refused(write_tsv(tmp_path, [*qtm_header(["A"], 3), "1\t2\tabc", *rows]),
            "'abc' is not a number", "line 11")

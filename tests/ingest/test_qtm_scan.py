"""The header scan of a QTM TSV export (`ingest/qtm_scan.py`): its keys, and a header
that cannot be right refused with its line."""

from __future__ import annotations

import pytest
from helpers.qtm_files import NEW_3D, OLD_6D, good_3d_lines, refused, write_tsv

from ingest.qtm_scan import parse_qtm_header

pytestmark = pytest.mark.usefixtures("real_samples")


def test_parse_qtm_header():
    h = parse_qtm_header(NEW_3D)
    assert h["NO_OF_FRAMES"] == "2000" and h["FREQUENCY"] == "100"
    assert h["TIME_STAMP"] == ["2026-01-19, 10:19:43.755", "2063631.96175450"]
    assert h["MARKER_NAMES"][0] == "New 0000" and len(h["MARKER_NAMES"]) == 15
    assert parse_qtm_header(OLD_6D)["BODY_NAMES"] == ["Upper Leg IMU", "Foot IMU",
                                                      "Lower Leg IMU"]


def test_bad_missing_file(tmp_path):
    refused(tmp_path / "absent.tsv", "no such file")


def test_bad_no_of_markers_contradicts_names(tmp_path):
    lines = [line.replace("NO_OF_MARKERS\t2", "NO_OF_MARKERS\t3") for line in good_3d_lines()]
    refused(write_tsv(tmp_path, lines), "NO_OF_MARKERS is 3", "line 3")


def test_bad_duplicate_marker_names(tmp_path):
    lines = good_3d_lines()
    lines[9] = "MARKER_NAMES\tA\tA"
    refused(write_tsv(tmp_path, lines), "duplicate", "A")

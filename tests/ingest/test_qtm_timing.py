"""The frames' times and the EVENT lines of a QTM TSV export (`ingest/qtm_timing.py`):
a Time column that is missing, not increasing or out of range, a FREQUENCY that cannot time
the frames, an EVENT time out of range."""

from __future__ import annotations

import pytest
from helpers.qtm_files import good_3d_lines, qtm_header, refused, write_tsv


def test_bad_non_increasing_time(tmp_path):
    lines = good_3d_lines(5)
    lines[13] = lines[13].replace("\t0.00400\t", "\t0.00200\t")
    refused(write_tsv(tmp_path, lines), "not increasing", "line 14")


def test_where_points_at_the_frame_time_of_the_bad_row(tmp_path):
    lines = good_3d_lines(5)
    lines[12] = lines[12].replace("\t0.00200\t", "\tnull\t")
    e = refused(write_tsv(tmp_path, lines), "Time is missing")
    assert e.where == "line 13"


def test_bad_time_out_of_int64_range(tmp_path):
    lines = good_3d_lines(2)
    lines[12] = lines[12].replace("\t0.00200\t", "\t1e300\t")
    refused(write_tsv(tmp_path, lines), "line 13", "1e+300 s", "int64 nanosecond range")


@pytest.mark.parametrize("rate, words", [("1e-300", "too low"), ("0", "not a frame rate"),
                                         ("1e12", "not a frame rate")])
def test_bad_frequency_of_a_file_timed_by_it(tmp_path, rate, words):
    lines = [ln.replace("FREQUENCY\t500", f"FREQUENCY\t{rate}") for ln in
             qtm_header(["A"], 2)] + ["1\t2\t3", "4\t5\t6"]
    refused(write_tsv(tmp_path, lines), "FREQUENCY", words, "line 4")


def test_bad_event_time(tmp_path):
    lines = good_3d_lines(2)
    lines.insert(9, "EVENT\tTrigger\t1\tinf")
    refused(write_tsv(tmp_path, lines), "EVENT 1", "int64 nanosecond range")

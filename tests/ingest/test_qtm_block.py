"""The data block of a QTM TSV export (`ingest/qtm_block.py`): rows against
NO_OF_FRAMES, a cut last line, cells that are no finite number."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.qtm_files import good_3d_lines, qtm_header, refused, write_tsv

from ingest.qtm_3d import read_qtm_3d


def test_bad_fewer_rows_than_no_of_frames(tmp_path):
    refused(write_tsv(tmp_path, good_3d_lines(4, claimed=6)), "truncated", "NO_OF_FRAMES")


def test_bad_partial_last_row(tmp_path):
    p = write_tsv(tmp_path, good_3d_lines(4))
    p.write_bytes(p.read_bytes()[:-20])
    e = refused(p, "truncated")
    assert e.where == "line 15"


def test_bad_last_row_cut_inside_a_number(tmp_path):
    p = write_tsv(tmp_path, good_3d_lines(4))
    p.write_bytes(p.read_bytes()[:-4])                      # "...6.750\r\n" -> "...6.7"
    refused(p, "truncated", "line 15")


def test_bad_more_rows_than_no_of_frames(tmp_path):
    refused(write_tsv(tmp_path, good_3d_lines(4, claimed=3)), "NO_OF_FRAMES says 3")


def test_bad_huge_no_of_frames_is_not_allocated(tmp_path):
    refused(write_tsv(tmp_path, good_3d_lines(4, claimed=10**13)), "truncated")


def test_bad_text_where_numbers_must_be(tmp_path):
    lines = good_3d_lines(6)
    lines[13] = lines[13].replace("5.625", "5.6x5")
    refused(write_tsv(tmp_path, lines), "'5.6x5'", "line 14", "not a number")


def test_bad_header_without_data(tmp_path):
    refused(write_tsv(tmp_path, good_3d_lines(4)[:11]), "truncated", "no data rows")


def test_no_no_of_frames_key_and_many_rows(tmp_path):
    """Without NO_OF_FRAMES the reader sizes its buffer from the data (and grows it)."""
    n = 70_000
    head = [line for line in qtm_header(["A"], 0) if not line.startswith("NO_OF_FRAMES")]
    rows = [f"{i}.5\t1\t2" for i in range(n)]
    s = read_qtm_3d(write_tsv(tmp_path, head + rows))
    assert s.frames == n and s.positions[-1, 0, 0] == pytest.approx((n - 1 + 0.5) / 1000)
    assert s.time_ns[-1] == round((n - 1) / 500 * 1e9)


def test_last_line_without_line_break_is_accepted_when_complete(tmp_path):
    p = write_tsv(tmp_path, good_3d_lines(4))
    p.write_bytes(p.read_bytes()[:-2])                      # drop the final "\r\n"
    s = read_qtm_3d(p)
    assert s.frames == 4 and s.positions[3, 1, 2] == pytest.approx(0.00675)


def test_last_line_without_line_break_ending_in_a_gap(tmp_path):
    rows = ["1.000\t2.000\t3.000\t1.000\t2.000\t3.000", "4.000\t5.000\t6.000\tNaN\tNaN\tNaN"]
    p = write_tsv(tmp_path, [*qtm_header(["a", "b"], 2, 100), *rows], end="\n")
    p.write_bytes(p.read_bytes()[:-1])                      # complete, no final line break
    s = read_qtm_3d(p)
    assert s.frames == 2 and np.isnan(s.positions[1, 1]).all()


@pytest.mark.parametrize("value", ["inf", "-inf", "1e400"])
def test_bad_infinite_coordinate(tmp_path, value):
    lines = good_3d_lines(4)
    lines[12] = lines[12].replace("\t2.250\t", f"\t{value}\t", 1)
    refused(write_tsv(tmp_path, lines), "line 13", "column 4", "not a finite number")

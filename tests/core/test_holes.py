"""Holes in a stream's clock: told from jitter, counted, and the stretches between them."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import BadInput
from core.holes import counted_numbers, find_holes, grid_numbers

MS = 1_000_000


def test_a_uniform_stream_has_no_hole() -> None:
    timing = find_holes(np.arange(1000) * 2 * MS, "m.tsv")
    assert timing.period_ns == 2 * MS and timing.holes == ()
    assert timing.stretches(1000) == [(0, 1000)]


def test_a_jump_is_a_hole_of_lost_samples() -> None:
    """200 frames lost at 500 Hz after frame 99: one hole of 0.4 s; the stretches around it."""
    t = np.r_[np.arange(100), np.arange(300, 400)] * 2 * MS
    (hole,) = find_holes(t, "m.tsv").holes
    assert (hole.index, hole.start_ns, hole.stop_ns, hole.lost) == (100, 198 * MS, 600 * MS, 200)
    assert hole.length_s == pytest.approx(0.400)
    assert find_holes(t, "m.tsv").stretches(200) == [(0, 100), (100, 200)]
    assert hole.describe("mocap frames") == \
        "0.400 s of mocap frames lost (200 samples) after 0.198 s"


def test_one_lost_sample_and_a_pause_are_holes() -> None:
    """A step of two periods is one sample lost; a pause of 3.4 periods is a hole of 2.4
    periods (rounded to 2 samples)."""
    one = find_holes(np.r_[np.arange(10), np.arange(11, 20)] * MS, "f.csv").holes
    assert [(h.index, h.lost) for h in one] == [(10, 1)]
    pause = find_holes(np.r_[np.arange(10) * 10, 90 + 34 + np.arange(10) * 10] * MS,
                       "f.csv").holes
    assert [(h.index, h.lost) for h in pause] == [(10, 2)]
    assert pause[0].length_s == pytest.approx(0.024)


@pytest.mark.parametrize("step", [1.2, 1.5, 1.85, 0.85])
def test_jitter_is_refused_with_its_sample(step: float) -> None:
    """A step that is neither one period (within 10 %: exact stamps, a whole number of their
    0.1 ms resolution a period) nor a jump of two or more is jitter."""
    t = np.arange(50, dtype=np.float64) * MS
    t[20:] += (step - 1) * MS
    with pytest.raises(BadInput) as e:
        find_holes(t.astype(np.int64), "f.csv", "force samples",
                   where=lambda i: f"line {i + 2}")
    assert e.value.path == "f.csv" and e.value.where == "line 22"
    assert "force samples are not evenly spaced" in e.value.what


def test_written_times_within_their_print_resolution_are_uniform() -> None:
    """300 Hz stamps printed to the millisecond (3 or 4 ms steps) are uniform with a 1 ms
    resolution, and a lost frame among them is still a hole."""
    t = np.round(np.arange(300) / 300, 3)
    t = np.delete(t, 150)
    timing = find_holes(np.round(t * 1e9).astype(np.int64), "m.tsv")
    assert [h.index for h in timing.holes] == [150]


def test_sample_numbers_from_a_column_and_from_a_grid() -> None:
    """QTM's SAMPLE column: numbers from the first, a skip kept; times on a rate's grid give
    the same numbers; a time off the grid, a column at another rate, a number that goes back
    are refused."""
    np.testing.assert_array_equal(counted_numbers(np.r_[1.0, 2, 3, 7, 8], "a.tsv"),
                                  [0, 1, 2, 6, 7])
    np.testing.assert_array_equal(grid_numbers(np.r_[0, 1, 2, 6, 7] / 1200 + 5.0, 1200.0,
                                               "p.tsv", print_s=5e-6), [0, 1, 2, 6, 7])
    with pytest.raises(BadInput, match="departs from the rate"):
        grid_numbers(np.r_[0, 1, 2.5, 3] / 1000, 1000.0, "p.tsv")
    with pytest.raises(BadInput, match="runs at 500 Hz, not at the stated 1000 Hz"):
        grid_numbers(np.arange(10) / 500, 1000.0, "p.tsv")
    with pytest.raises(BadInput, match="does not increase"):
        counted_numbers(np.r_[1.0, 2, 2, 3], "a.tsv")


def test_a_millisecond_print_hides_no_jitter_and_no_lost_sample() -> None:
    """At 500 Hz written to the millisecond, a frame 1 ms late is jitter (the print's rounding
    widens the tolerance to at most 45 % of a period); at 1 kHz so written, one lost sample
    is still a hole."""
    t = np.arange(100) * 2 * MS
    t[50:] += MS
    with pytest.raises(BadInput, match="jitter"):
        find_holes(t, "m.tsv")
    (hole,) = find_holes(np.r_[np.arange(10), np.arange(11, 30)] * MS, "f.csv").holes
    assert hole.lost == 1 and hole.whole


def test_a_long_hole_at_300_hz_counts_its_frames_exactly() -> None:
    """QTM writes 300 Hz times with 5 decimals (steps of 3.33 and 3.34 ms): 1500 frames lost
    are 1500, not the 1502 the median step would give."""
    frames = np.r_[np.arange(3000), np.arange(4500, 6000)]
    t = np.round(np.round(frames / 300, 5) * 1e9).astype(np.int64)
    (hole,) = find_holes(t, "m.tsv").holes
    assert hole.lost == 1500 and hole.whole
    assert not find_holes(np.r_[np.arange(10) * 10, 124 + np.arange(10) * 10] * MS,
                          "f.csv").holes[0].whole

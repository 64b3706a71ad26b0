"""What the live session keeps of its recent past and how it counts what it took
(:mod:`live.session.states`), against hand-made numbers: the stamped rows (``Ring``) grow past
their capacity in order, a stretch is every row between two times (both ends kept), forgetting
drops only the older rows; the history pads the force by the resampler's reach and keeps the
flags apart; the coverage of the presses taken is per location, its levels counted. The
states themselves, against ``pipeline sync`` + ``pipeline extract``: ``test_live_session.py``;
frame by frame against the twin's truth: ``test_monitor.py``."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from live.session.states import FORCE_PAD_S, History, Ring, coverage


def test_rows_past_the_capacity_keep_their_order_and_values() -> None:
    ring = Ring((2,), capacity=4)
    times = np.arange(0, 100, 10, dtype=np.int64)             # 10 rows in three adds
    rows = np.arange(20, dtype=float).reshape(10, 2)
    for part in (slice(0, 3), slice(3, 4), slice(4, 10)):
        ring.add(times[part], rows[part])
    t, r = ring.between(0, 90)
    np.testing.assert_array_equal(t, times)
    np.testing.assert_array_equal(r, rows)
    assert ring.oldest_ns == 0


@pytest.mark.parametrize(("start", "stop", "want"), [
    (20, 50, [20, 30, 40, 50]),      # both ends kept
    (21, 49, [30, 40]),
    (95, 200, []),
    (-5, 0, [0]),
])
def test_a_stretch_is_every_row_between_two_times(start, stop, want) -> None:
    ring = Ring((1,), capacity=16)
    ring.add(np.arange(0, 100, 10, dtype=np.int64), np.arange(10, dtype=float)[:, None])
    t, r = ring.between(start, stop)
    assert t.tolist() == want and r[:, 0].tolist() == [x / 10 for x in want]
    t[:] = -1                                            # a copy: the ring is untouched
    assert ring.between(start, stop)[0].tolist() == want


def test_forgetting_drops_only_the_older_rows_and_adding_goes_on() -> None:
    ring = Ring((1,), capacity=4)
    ring.add(np.arange(0, 60, 10, dtype=np.int64), np.arange(6, dtype=float)[:, None])
    ring.forget(25)
    assert ring.oldest_ns == 30 and ring.size == 3
    ring.add(np.array([60], np.int64), np.array([[6.0]]))
    t, r = ring.between(0, 100)
    assert t.tolist() == [30, 40, 50, 60] and r[:, 0].tolist() == [3, 4, 5, 6]
    ring.forget(1000)
    assert ring.oldest_ns is None and ring.size == 0


def test_the_history_pads_the_force_by_the_resampler_s_reach() -> None:
    """Frames every 2 ms and force every 1 ms over 1 s: a stretch of 100-200 ms holds the
    frames in it and the force FORCE_PAD_S beyond it on each side, values and flags apart."""
    history = History(markers=2, channels=3)
    for k in range(500):
        history.add_frame(k * 2_000_000, np.full((2, 3), float(k)))
    t_f = np.arange(1000, dtype=np.int64) * 1_000_000
    values = np.c_[t_f * 1e-9, 2 * t_f * 1e-9, np.zeros(1000)]
    flags = (t_f // 1_000_000) % 7 == 0
    history.add_force(t_f, values, flags)
    t_m, markers, t_s, force, flagged = history.stretch(100_000_000, 200_000_000)
    assert t_m[0] == 100_000_000 and t_m[-1] == 200_000_000 and len(t_m) == 51
    assert markers.shape == (51, 2, 3) and markers[0, 0, 0] == 50.0
    pad = int(FORCE_PAD_S * 1e9)
    assert t_s[0] == max(0, 100_000_000 - pad) and t_s[-1] == 200_000_000 + pad
    np.testing.assert_allclose(force[:, 0], t_s * 1e-9)
    assert force.shape[1] == 3 and flagged.dtype == bool
    np.testing.assert_array_equal(flagged, (t_s // 1_000_000) % 7 == 0)
    assert history.older_than(1) and not history.older_than(0)
    history.forget(150_000_000)
    assert not history.older_than(150_000_000)


def _taken(location: int, centre: tuple[float, float, float], steps: list[int]):
    return SimpleNamespace(location=location, centre=np.array(centre),
                           states=SimpleNamespace(step=np.array(steps)))


def test_the_coverage_is_per_location_with_its_levels_counted() -> None:
    """Location 0 pressed twice (levels 0-3 and 0-5), location 1 once (levels 0-2, level 1
    missed): their mean contact point, press counts, states per level and top level."""
    taken = [_taken(0, (0.01, 0.02, 0.0), [0, 1, 2, 3]), _taken(1, (0.05, 0.05, 0.0), [0, 2]),
             _taken(0, (0.03, 0.02, 0.0), [0, 1, 2, 3, 4, 5])]
    first, second = coverage(taken)
    np.testing.assert_allclose(first.centre, [0.02, 0.02, 0.0])
    assert first.presses == 2 and first.states.tolist() == [2, 2, 2, 2, 1, 1]
    assert first.top_level(0.5) == 2.5
    assert second.presses == 1 and second.states.tolist() == [1, 0, 1]
    assert second.top_level(0.5) == 1.0
    assert coverage([]) == []
    assert coverage([_taken(2, (0, 0, 0), [])])[0].top_level(0.5) == 0.0

"""Which clock a session gets and why (:mod:`sync.clock_policy`), on the analytic session of
``tests/helpers/raw_sessions.py`` (logger clock ``OFFSET + (1 + DRIFT ppm) t_m``, known): force from
the mocap's own analog board shares its clock; trigger pulses when recorded; the tip's motion
against the force when they are not, when the line is dead, or when asked; each with the
reason the calibration record keeps. And the overlap check, on hand-picked spans.

The far offsets, a one-press log, another session's force and a periodic trigger that the data
disambiguates are ``test_sync_extremes.py``'s (through whole syncs); here the policy is called
directly with the truth of the tip's depth and the force, so each branch is seen alone.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
from helpers.raw_sessions import DRIFT, LOG_RATE, OFFSET, RATE, analytic_session

from core.errors import BadInput
from core.series import SHARED_CLOCK, RawSession
from sync.clock import MIN_PULSES, ClockFit
from sync.clock_policy import (
    SHARED,
    check_overlap,
    clock_reason,
    estimate_clock,
    search_reach_s,
    shares_mocap_clock,
)
from sync.sync_params import SyncParams


def _depth(t_m: np.ndarray, presses: int) -> np.ndarray:
    """The analytic session's true tip depth below the surface (m) at mocap times: 30 mm
    above it at rest, each press ``0.036 sin^2`` down over 2 s from 1.5 + 4 k s."""
    z = np.full(len(t_m), 0.03)
    for k in range(presses):
        s = (t_m - (1.5 + 4 * k)) / 2.0
        inside = (s >= 0) & (s <= 1)
        z[inside] = 0.03 - 0.036 * np.sin(np.pi * s[inside]) ** 2
    return -z


def _inputs(raw: RawSession, presses: int = 4):
    """(t_m, depth, t_f, magnitude_at): the mocap frames' times and the true depth, the
    logger's times, and the true force magnitude at logger times (7 N at 6 mm deep, to the
    power 1.5; NaN outside the log, as the resampler gives)."""
    t_m = raw.markers.time_ns * 1e-9
    t_f = raw.force.time_ns * 1e-9

    def magnitude_at(t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, float)
        d = _depth((t - OFFSET) / (1 + DRIFT * 1e-6), presses)
        out = 7.0 * (np.clip(d, 0, None) / 0.006) ** 1.5
        return np.where((t >= t_f[0]) & (t <= t_f[-1]), out, np.nan)

    return t_m, _depth(t_m, presses), t_f, magnitude_at


def _shared(raw: RawSession) -> RawSession:
    """The session's force as a C3D's analog channels: sampled by the mocap system."""
    out = copy.deepcopy(raw)
    out.force.meta = {"clock": SHARED_CLOCK, "format": "c3d"}
    out.force.source = "trial.c3d"
    return out


@pytest.fixture(scope="module")
def raw() -> RawSession:
    return analytic_session(seed=2)


def test_force_from_the_mocap_s_analog_board_shares_its_clock(raw: RawSession) -> None:
    """Whether a trigger was recorded or not, --clock auto estimates nothing: offset 0,
    drift 0, exact; the reason names the format, the file and the rate."""
    shared = _shared(raw)
    assert shares_mocap_clock(shared) and not shares_mocap_clock(raw)
    clock, note = estimate_clock(shared, SyncParams(), *_inputs(shared))
    assert clock == SHARED and note is None
    assert (clock.offset_s, clock.drift_ppm, clock.offset_sd_s, clock.method) == \
        (0.0, 0.0, 0.0, "shared")
    assert clock_reason(shared, SyncParams(), clock, None) == (
        f"force from the mocap system's analog board (c3d trial.c3d, {LOG_RATE:g} Hz): one "
        "clock, no offset or drift to estimate")


def test_a_shared_clock_is_auto_s_choice_only(raw: RawSession) -> None:
    """--clock data on such a session still locks to the data (here: with the tip tracked
    in too few frames, which is then refused naming the mocap file)."""
    shared = _shared(raw)
    t_m, depth, t_f, mag = _inputs(shared)
    with pytest.raises(BadInput) as e:
        estimate_clock(shared, SyncParams(clock="data"), t_m, np.full_like(depth, np.nan),
                       t_f, mag)
    assert e.value.path == "trial.tsv" and "tracked in too few frames" in e.value.what


def test_recorded_trigger_pulses_set_the_clock(raw: RawSession) -> None:
    """The trigger edges matched to the mocap's EVENTs: the true offset within 0.5 ms and
    drift within its uncertainty; the reason names the EVENT label."""
    clock, note = estimate_clock(raw, SyncParams(), *_inputs(raw))
    assert clock.method == "trigger" and note is None
    assert abs(clock.offset_s - OFFSET) < 0.5e-3
    assert abs(clock.drift_ppm - DRIFT) < 4 * clock.drift_sd_ppm + 5
    assert clock_reason(raw, SyncParams(), clock, note) == (
        "trigger pulses in the force log matched to the 'Trigger' events of the mocap export")


def _few_pulses(raw: RawSession, keep: int) -> RawSession:
    """The trigger line with only its first ``keep`` pulses (a line unplugged early)."""
    out = copy.deepcopy(raw)
    ttl = out.force.trigger
    rises = np.flatnonzero(np.diff((ttl > 2.5).astype(int)) == 1)
    ttl[rises[keep] + 1:] = 0.0
    return out


@pytest.mark.parametrize("keep", [0, 1, MIN_PULSES - 1])
def test_a_dead_trigger_line_falls_back_to_the_data_and_says_why(raw: RawSession,
                                                                 keep: int) -> None:
    """Fewer than MIN_PULSES edges with --clock auto: the tip motion against the force gives
    the clock (the true offset within 2 ms), and the note (kept as the reason) counts the
    edges and the mocap's events."""
    dead = _few_pulses(raw, keep)
    events = sum(label == "Trigger" for label, _ in raw.markers.events)
    clock, note = estimate_clock(dead, SyncParams(), *_inputs(dead))
    assert clock.method == "data" and abs(clock.offset_s - OFFSET) < 2e-3
    assert note == (f"trigger unusable ({keep} pulse edges in the force log, {events} trigger "
                    "events in the mocap file): clock from the data")
    assert clock_reason(dead, SyncParams(), clock, note) == note


def test_a_dead_line_is_refused_when_the_trigger_is_asked_for(raw: RawSession) -> None:
    """--clock trigger takes no fallback: two pulses are too few, said for the force log."""
    dead = _few_pulses(raw, 2)
    with pytest.raises(BadInput) as e:
        estimate_clock(dead, SyncParams(clock="trigger"), *_inputs(dead))
    assert e.value.path == "force.csv" and "2 pulse edges" in e.value.what


def test_clock_data_is_used_even_with_a_trigger_recorded(raw: RawSession) -> None:
    """--clock data ignores a recorded trigger: the tip motion gives the true offset within 2 ms,
    and the reason says it was asked for."""
    clock, note = estimate_clock(raw, SyncParams(clock="data"), *_inputs(raw))
    assert clock.method == "data" and note is None
    assert abs(clock.offset_s - OFFSET) < 2e-3
    assert clock_reason(raw, SyncParams(clock="data"), clock, note) == (
        "--clock data: offset and drift from the tip motion against the force")


def test_without_a_trigger_the_data_sets_the_clock(raw: RawSession) -> None:
    """No trigger channel: the data clock, the true offset within 2 ms, the reason says none was
    recorded."""
    bare = analytic_session(seed=2, trigger=False)
    clock, note = estimate_clock(bare, SyncParams(), *_inputs(bare))
    assert clock.method == "data" and note is None
    assert abs(clock.offset_s - OFFSET) < 2e-3
    assert clock_reason(bare, SyncParams(), clock, note) == (
        "no trigger recorded: offset and drift from the tip motion against the force")


def test_a_trigger_label_the_mocap_never_recorded_is_no_trigger(raw: RawSession) -> None:
    """A pulse channel in the log but no EVENT of the session's trigger label in the mocap
    file: --clock trigger is refused for the force log, --clock auto uses the data."""
    other = copy.deepcopy(raw)
    other.trigger_event = "Sync"
    with pytest.raises(BadInput) as e:
        estimate_clock(other, SyncParams(clock="trigger"), *_inputs(other))
    assert e.value.path == "force.csv"
    assert "no trigger channel with matching mocap events" in e.value.what
    clock, note = estimate_clock(other, SyncParams(), *_inputs(other))
    assert clock.method == "data" and note is None


def test_a_periodic_trigger_without_a_tracked_tip_is_refused_for_the_trigger(
        raw: RawSession) -> None:
    """Pulses exactly 1 s apart, the log missing the first and last three (whole periods tie),
    and the tip tracked in too few frames to say which: refused naming the force log, the
    pulse spacing, and what to record instead."""
    periodic = copy.deepcopy(raw)
    t_m = periodic.markers.time_ns * 1e-9
    events = np.arange(1.0, t_m[-1] - 0.5, 1.0)
    periodic.markers.events = [("Trigger", int(round(e * 1e9))) for e in events]
    t_f = periodic.force.time_ns * 1e-9
    ttl = np.zeros(len(t_f))
    for at in OFFSET + (1 + DRIFT * 1e-6) * events[3:-3]:
        ttl[(t_f >= at) & (t_f < at + 0.01)] = 5.0
    periodic.force.trigger = ttl
    t_m, depth, t_f, mag = _inputs(periodic)
    with pytest.raises(BadInput) as e:
        estimate_clock(periodic, SyncParams(), t_m, np.full_like(depth, np.nan), t_f, mag)
    assert e.value.path == "force.csv"
    assert "pulse train is periodic (pulses 1.000 s apart)" in e.value.what
    assert "too few frames" in e.value.what and "irregular intervals" in e.value.what


def test_the_data_clock_searches_every_offset_unless_bounded() -> None:
    """No --max-offset: an unbounded search (inf); given: that bound, in seconds."""
    assert search_reach_s(SyncParams()) == np.inf
    assert search_reach_s(SyncParams(max_offset_s=30)) == 30.0


@pytest.mark.parametrize(("offset", "t_f", "ok"), [
    (0.0, (1.0, 5.0), True),        # mocap 0..2 s on the logger: 1 s in common, just enough
    (-0.5, (1.0, 5.0), False),      # -0.5..1.5 s: 0.5 s in common
    (10.0, (0.0, 5.0), False),      # 10..12 s: none
    (10.0, (9.0, 30.0), True),      # 10..12 s inside the log
])
def test_streams_sharing_less_than_a_second_are_refused(offset: float, t_f: tuple,
                                                        ok: bool) -> None:
    """Mocap frames at 0..2 s through the clock, against a log spanning ``t_f``."""
    raw = analytic_session(presses=1)
    clock = ClockFit(offset, 0.0, 0.0, 0.0, 0.0, 3, "trigger")
    t_m = np.linspace(0.0, 2.0, int(2 * RATE) + 1)
    log = np.linspace(*t_f, 100)
    if ok:
        check_overlap(raw, clock, t_m, log)
        return
    with pytest.raises(BadInput) as e:
        check_overlap(raw, clock, t_m, log)
    span = max(min(offset + 2.0, t_f[1]) - max(offset, t_f[0]), 0.0)
    assert e.value.path == "force.csv"
    assert e.value.what == ("force log and mocap recording do not overlap in time (common "
                            f"span {span:.3f} s on the trigger clock)")

"""Static states of each press while the session goes on, by sync's and extract's rules.

A press's states need a little of what follows it: the re-tare reads the rest after the
release, and the filters reach past it. So a press is taken :data:`AFTER_S` after it ended
(:class:`live.session.presses.PressTracker` says when), from the stretch of the session around
it (from :data:`BEFORE_S` before its contact, never before the previous press's end, to
:data:`AFTER_S` after it), kept in :class:`History`. That stretch goes through sync's steps
(:func:`press_record`): every frame's tip (:meth:`live.session.calibration.TipModel.tips`), short
marker gaps filled, the tip low-passed, the force tared with the session's tare, re-tared from
the rest around the press, low-passed and sampled at the frame times, the press found by
sync's segmentation, placed by its contact point and given a location as sync gives it. Then
extract reads its states (:func:`extract.static_states.press_states`) in the phantom frame.
The filters, the gap filler and the re-tare work locally, so on a stretch this long they give
what they give on the whole session: the same presses and levels as ``pipeline sync`` and
``pipeline extract`` on the session's MCAP (checked by ``tests/live/test_live_session.py``).

At the end :meth:`OnlineStates.session` hands the presses to extract as a synced file's would
be, with the phantom frame fitted as extract fits it (:func:`extract.synced_presses.
session_from_presses`).
"""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from calib.force_tare import Tare
from core.errors import BadInput
from core.progress import warn
from core.series import ForceSeries, MarkerSeries, RawSession
from data_schema.session import SessionConfig
from extract.extract_params import ExtractParams
from extract.phantom_frame import apply_transform
from extract.static_states import PressSeries, PressStates, press_states
from extract.synced_presses import Session, session_from_presses
from live.session.calibration import TipModel, wrench
from live.session.layout import LiveLayout
from live.session.presses import PressDone
from sync.force_conditioning import retared
from sync.holes import hole_line, leave_out_touched, session_holes, touch_reach
from sync.presses import Press as Loaded
from sync.presses import PressRule, assign_locations, cut_span, segment_presses
from sync.resample import antialiased_interpolant
from sync.surface import RestSurface
from sync.sync import frame_force, session_points
from sync.sync_params import SyncParams

BEFORE_S = 1.5      # of the session before a contact its press is read with (re-tare, margins)
AFTER_S = 1.5       # ... and after its end: the press is taken this long after it ended
FORCE_PAD_S = 0.2   # force samples beyond the frames' stretch (the resampler's reach)
KEEP_S = 30.0       # the history kept while no press waits (the longest press it can take)


class Ring:
    """Rows stamped in increasing time (ns), kept in one array that grows as needed: appending
    a row is a copy into place, a stretch of time a slice."""

    def __init__(self, shape: tuple[int, ...], capacity: int = 4096) -> None:
        self.time = np.empty(capacity, np.int64)
        self.rows = np.empty((capacity, *shape))
        self.size = 0

    def add(self, times_ns: np.ndarray, rows: np.ndarray) -> None:
        n = len(times_ns)
        if self.size + n > len(self.time):
            grow = max(2 * len(self.time), self.size + n)
            self.time = np.resize(self.time, grow)
            self.rows = np.resize(self.rows, (grow, *self.rows.shape[1:]))
        self.time[self.size:self.size + n] = times_ns
        self.rows[self.size:self.size + n] = rows
        self.size += n

    def between(self, start_ns: int, stop_ns: int) -> tuple[np.ndarray, np.ndarray]:
        """Copies of the times and rows from ``start_ns`` to ``stop_ns`` (both included)."""
        t = self.time[:self.size]
        a, b = np.searchsorted(t, start_ns, "left"), np.searchsorted(t, stop_ns, "right")
        return t[a:b].copy(), self.rows[a:b].copy()

    def forget(self, before_ns: int) -> None:
        """Drop the rows before ``before_ns``."""
        a = int(np.searchsorted(self.time[:self.size], before_ns, "left"))
        keep = self.size - a
        self.time[:keep] = self.time[a:self.size]
        self.rows[:keep] = self.rows[a:self.size]
        self.size = keep

    @property
    def oldest_ns(self) -> int | None:
        return int(self.time[0]) if self.size else None


class History:
    """The session's recent frames (phantom markers, then the cluster's) and force samples
    (SI values before the tare, then 1 where saturated or over range), oldest first."""

    def __init__(self, markers: int, channels: int) -> None:
        self.frames = Ring((markers, 3))
        self.force = Ring((channels + 1,))

    def add_frame(self, time_ns: int, markers: np.ndarray) -> None:
        self.frames.add(np.array([time_ns]), markers[None])

    def add_force(self, times_ns: np.ndarray, values: np.ndarray, flagged: np.ndarray) -> None:
        self.force.add(times_ns, np.column_stack([values, flagged]))

    def stretch(self, start_ns: int, stop_ns: int) -> tuple[np.ndarray, ...]:
        """Frame times, markers (T, M, 3), force times, values and flags between the two (the
        force :data:`FORCE_PAD_S` beyond them: the resampler's reach)."""
        t_m, markers = self.frames.between(start_ns, stop_ns)
        pad = int(FORCE_PAD_S * 1e9)
        t_f, force = self.force.between(start_ns - pad, stop_ns + pad)
        return t_m, markers, t_f, force[:, :-1], force[:, -1] > 0

    def forget(self, before_ns: int) -> None:
        """Drop what lies before ``before_ns``."""
        self.frames.forget(before_ns)
        self.force.forget(before_ns)

    def older_than(self, time_ns: int) -> bool:
        """Whether the oldest frame kept is before ``time_ns``."""
        oldest = self.frames.oldest_ns
        return oldest is not None and oldest < time_ns


@dataclass(frozen=True)
class Surface:
    """The phantom at rest: sync's rest surface (its plane, or a curved phantom's registered
    shape), and the lab -> phantom frame transform (4, 4) the live view uses."""

    rest: RestSurface
    transform: np.ndarray


@dataclass(frozen=True)
class Conditioning:
    """What the force's samples go through before they become a press's force: the session's
    tare, its noise (N) and contact level (N)."""

    tare: Tare
    noise_n: float
    contact_n: float


@dataclass(frozen=True)
class Cut:
    """A press cut out of its stretch with sync's margins: its loaded span on the cut's frames,
    their times (ns), points (lab frame, the tip last) and force magnitude (N)."""

    press: Loaded
    time_ns: np.ndarray
    points: np.ndarray
    force_magnitude: np.ndarray


@dataclass(frozen=True)
class Touched:
    """A press a hole in the stream touches: left out, as sync leaves it out (its loaded span
    on the stretch's frames, for its place; the holes, one line each)."""

    cut: Cut
    holes: list[str]


@dataclass
class LivePress:
    """A press taken online: extract's press in the lab frame, where it touched, its location
    id, and its states in the phantom frame (empty for a press whose force is untrusted)."""

    number: int
    press: PressSeries
    centre: np.ndarray
    location: int
    states: PressStates


@dataclass
class PlaceCoverage:
    """A location pressed: where (its presses' mean contact point, lab frame), how many
    presses, and its states per force level (index k: k x the level spacing)."""

    centre: np.ndarray
    presses: int
    states: np.ndarray

    def top_level(self, step_n: float) -> float:
        """The highest force level (N) read at this location (0: only the rest)."""
        seen = np.flatnonzero(self.states)
        return float(seen[-1]) * step_n if seen.size else 0.0


def coverage(taken: list[LivePress]) -> list[PlaceCoverage]:
    """Every location pressed so far, in the order they were first pressed."""
    out: dict[int, list[LivePress]] = {}
    for t in taken:
        out.setdefault(t.location, []).append(t)
    result = []
    for loc in sorted(out):
        here = out[loc]
        steps = np.concatenate([t.states.step for t in here]).astype(int)
        result.append(PlaceCoverage(np.mean([t.centre for t in here], axis=0), len(here),
                               np.bincount(steps, minlength=1)))
    return result


class OnlineStates:
    """Presses queued as they end, taken once their stretch is complete: sync's and extract's
    steps on a worker thread (a press costs many frames' time: the frames go on meanwhile),
    the results taken back in order."""

    def __init__(self, cfg: SessionConfig, layout: LiveLayout, tip: TipModel, history: History,
                 surface: Surface, force: Conditioning, sync: SyncParams | None = None,
                 extract: ExtractParams | None = None) -> None:
        self.cfg, self.layout, self.tip, self.surface, self.force = cfg, layout, tip, surface, force
        self.sync, self.extract = sync or SyncParams(), extract or ExtractParams()
        self.phantom = len(cfg.mocap.phantom_markers)
        self.history = history
        self.waiting: list[PressDone] = []
        self.taken: list[LivePress] = []
        self.missed = 0                      # presses sync's rules did not find in the stretch
        self.unread: list[str] = []          # presses whose stretch was refused: why, in words
        self.touched: list[str] = []         # presses a hole touched (left out): why, in words
        self.placed: list[np.ndarray] = []   # the contact point of every whole press found
        self.notes: list[str] = []           # those not yet shown (the view's status log)
        self._last_end = 0
        self._pool = ThreadPoolExecutor(max_workers=1)
        self._running: list[tuple[PressDone, Future]] = []

    def ended(self, press: PressDone) -> None:
        """A press the tracker saw end: taken once :data:`AFTER_S` more has arrived."""
        self.waiting.append(press)

    def poll(self, now_ns: int) -> list[LivePress]:
        """The presses taken by ``now_ns`` (in the order they ended); those whose stretch is
        complete are handed to the worker."""
        due = [p for p in self.waiting if now_ns >= p.end_ns + AFTER_S * 1e9]
        for press in due:
            self._submit(press, press.end_ns + int(AFTER_S * 1e9))
        self.waiting = [p for p in self.waiting if p not in due]
        keep_from = min([p.start_ns for p in self.waiting], default=now_ns) - \
            int((BEFORE_S + KEEP_S) * 1e9)
        if self.history.older_than(keep_from - int(KEEP_S * 1e9)):   # now and then: cheap
            self.history.forget(keep_from)
        return self._collect(wait=False)

    def finish(self, now_ns: int) -> list[LivePress]:
        """At the session's end: the presses still waiting taken with what arrived, and every
        press the worker still has."""
        for press in self.waiting:
            self._submit(press, now_ns)
        self.waiting = []
        taken = self._collect(wait=True)
        self._pool.shutdown()
        return taken

    def _submit(self, done: PressDone, stop_ns: int) -> None:
        """The press's stretch (a copy) to the worker: the stream goes on meanwhile."""
        start = max(done.start_ns - int(BEFORE_S * 1e9), self._last_end)
        self._last_end = done.end_ns
        stretch = self.history.stretch(start, stop_ns)
        self._running.append((done, self._pool.submit(self._read, stretch, done)))

    def stretch_session(self, time_ns: np.ndarray, markers: np.ndarray, force_ns: np.ndarray,
                        values: np.ndarray) -> RawSession:
        """A stretch of the history as sync's steps read a session: the frames (phantom
        markers, then the cluster's) and the force samples, each timed by its numbers."""
        names = list(self.cfg.mocap.phantom_markers) + list(self.cfg.mocap.indenter_markers)
        d = self.layout.device
        return RawSession(
            name=self.cfg.name, phantom_markers=names[:self.phantom],
            indenter_markers=names[self.phantom:],
            markers=MarkerSeries(self.layout.source, time_ns, names, markers,
                                 self.layout.rate_hz),
            force=ForceSeries(self.layout.source, force_ns, list(d.labels), values,
                              list(d.units), "gauge" if self.layout.calibration else "wrench",
                              d.rate_hz))

    def _read(self, stretch: tuple[np.ndarray, ...], done: PressDone
              ) -> tuple[Cut, bool, PressStates] | Touched | None:
        """The worker's part: the press by sync's steps and its states by extract's."""
        found = press_record(stretch, done, self)
        if found is None or isinstance(found, Touched):
            return found
        cut, untrusted = found
        press = _press(cut, untrusted)
        in_frame = replace(press, points=apply_transform(self.surface.transform, press.points))
        return cut, untrusted, press_states(in_frame, self.extract,
                                            levels=not untrusted and press.peak > press.onset)

    def _collect(self, wait: bool) -> list[LivePress]:
        """The worker's finished presses, in order, placed at their locations."""
        out = []
        while self._running and (wait or self._running[0][1].done()):
            done, future = self._running.pop(0)
            try:
                read = future.result()
            except (BadInput, ValueError) as e:   # a stretch sync would refuse offline
                self._unread(done, e.line() if isinstance(e, BadInput) else str(e))
                continue
            if read is None:
                self.missed += 1
                continue
            cut = read.cut if isinstance(read, Touched) else read[0]
            try:
                centre, location = self._place(cut)
            except BadInput as e:                  # a curved phantom's press off its mould
                self._unread(done, e.line())
                continue
            if isinstance(read, Touched):
                self._left_out(done, read.holes)
                continue
            cut, untrusted, states = read
            self.taken.append(LivePress(done.number, _press(cut, untrusted), centre, location,
                                        states))
            out.append(self.taken[-1])
        return out

    def _place(self, cut: Cut) -> tuple[np.ndarray, int]:
        """Where a press touched and its location, as sync places it among every whole press
        found so far (those a hole touched too)."""
        tip = cut.points[:, -1]
        centre = self.surface.rest.touches(tip, self.surface.rest.depth(tip), [cut.press])[0][0]
        self.placed.append(centre)
        location = assign_locations(np.array(self.placed), self.sync.location_radius_m)[0][-1]
        return centre, int(location)

    def _left_out(self, done: PressDone, holes: list[str]) -> None:
        """A press a hole touched: said in one line (with the hole), left out of the states,
        as sync leaves it out; the session goes on."""
        note = f"press {done.number}: left out, a hole touches it: {'; '.join(holes)}"
        self.touched.append(note)
        self.notes.append(note)
        warn(note)

    def _unread(self, done: PressDone, why: str) -> None:
        """A press whose stretch sync's steps refused (bad input they would refuse offline
        too): said in one line, left out of the states; the session goes on."""
        note = f"press {done.number}: its states were not read: {why}"
        self.unread.append(note)
        self.notes.append(note)
        warn(note)

    def session(self, path: Path) -> Session:
        """The presses taken, as extract reads a synced file's (the phantom frame fitted from
        their rest, as extract fits it)."""
        names = list(self.cfg.mocap.phantom_markers) + ["tip"]
        return session_from_presses(path, self.cfg.name, [replace(t.press) for t in self.taken],
                                    [t.location for t in self.taken], names,
                                    self.surface.rest.point, self.surface.rest.normal,
                                    self.cfg.phantom, self.force.noise_n,
                                    None if self.surface.rest.registration is None
                                    else self.surface.transform)


def _press(cut: Cut, untrusted: bool) -> PressSeries:
    """Extract's press of a cut (lab frame)."""
    return PressSeries(time_s=cut.time_ns * 1e-9, points=cut.points, force=cut.force_magnitude,
                 onset=cut.press.onset, peak=cut.press.peak, untrusted_force=untrusted)


def press_record(stretch: tuple[np.ndarray, ...], done: PressDone, on: OnlineStates
                 ) -> tuple[Cut, bool] | Touched | None:
    """The press ``done`` in its stretch of the session, by sync's steps (the same functions,
    in the same order, as :func:`sync.sync.sync_session` on a whole session, with the session's
    tip model and tare and the one clock QTM gives both streams): its record (lab frame, cut
    with sync's margins) and whether a force sample near its loaded span was saturated or over
    range; :class:`Touched` where a hole in either stream touches it (sync leaves it out);
    None where sync's segmentation finds no complete press at its peak."""
    t_ns, markers, f_ns, values, flags = stretch
    p, rate = on.sync, on.layout.rate_hz
    raw, holes = session_holes(on.stretch_session(t_ns, markers, f_ns, values), p.max_gap_s)
    t_m, frames = raw.markers.time_ns * 1e-9, raw.markers.positions
    tip = on.tip.tips(frames[:, on.phantom:], p)
    points, _ = session_points(t_m, frames[:, :on.phantom], tip, holes.lost, rate, p)
    cf = retared(raw, p, on.force.tare, wrench(raw.force.values, on.force.tare, on.layout),
                 on.force.noise_n)
    force_at = antialiased_interpolant(cf.time_s, cf.wrench, rate, p.passband, cf.stretches)
    on_frames = frame_force(force_at, cf, raw, holes, t_m, p)
    magnitude = on_frames.magnitude
    presses, _ = segment_presses(magnitude, rate, PressRule(p.detect_n, cf.contact))
    peak_s = done.peak_ns * 1e-9
    hit = [k for k, pr in enumerate(presses) if t_m[pr.onset] <= peak_s <= t_m[pr.release - 1]]
    if not hit:
        return None
    loaded = presses[hit[0]]
    if not leave_out_touched([loaded], on_frames.spans, touch_reach(rate, p)):
        lines = [hole_line(s, raw.markers.time_ns, np.full(len(t_m), np.nan), presses)
                 for s in on_frames.spans if s.presses]
        return Touched(Cut(loaded, raw.markers.time_ns, points, magnitude), lines)
    local, lo, hi = cut_span(presses, hit[0], len(t_m), int(round(p.margin_s * rate)))
    t_f = f_ns * 1e-9
    span = (t_f >= t_m[loaded.onset] - FORCE_PAD_S) & (t_f <= t_m[loaded.release - 1] + FORCE_PAD_S)
    return Cut(local, raw.markers.time_ns[lo:hi], points[lo:hi], magnitude[lo:hi]), \
        bool(flags[span].any())

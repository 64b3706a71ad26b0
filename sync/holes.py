"""Holes in a session's streams: found, named, and kept out of every state (sync's first step).

A hole is a stretch of samples a stream never recorded (:mod:`core.holes`: found from the
stream's own clock; jitter stays bad input). Sync never interpolates across one:

- the mocap's lost frames come back as frames with no marker in them (:func:`regular_frames`),
  so every later step keeps its uniform frame axis and sees the hole as missing data, flagged
  ``lost`` in the synced file's quality bits, never filled in (nor a marker gap that runs into
  it);
- the force log is resampled stretch by stretch (:mod:`sync.resample`); the frames whose force
  the resampler read from a hole's edge are flagged ``in_hole`` in the force bits;
- a hole of at most :data:`BRIDGED` lost samples that is a whole number of periods (a real-time
  client that drops a frame under load, a DAQ that slips one sample) is bridged: a straight
  line between its neighbours for the force, the marker gap filler for the mocap (where it
  fills that short a gap); it is still named and recorded, and costs no press;
- a press is left out when a hole reaches into its record (its loaded span with sync's
  margins, and at least the tip filter's reach: every frame its states are read from), after
  it has been given its location (so the other presses keep theirs), and said
  (:func:`leave_out_touched`, :func:`hole_line`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from core.holes import Hole, Timing, find_holes
from core.series import ForceSeries, MarkerSeries, RawSession
from sync.presses import Press
from sync.smooth import smoothing_taps
from sync.sync_params import SyncParams

BRIDGED = 2    # lost samples a hole may have and still be bridged
PRESSING_M = 1e-3   # a tip this deep below the rest plane during a hole was pressing


@dataclass(frozen=True)
class SessionHoles:
    """The holes of a session's two streams, each on its own clock: those kept (the presses
    they reach are left out) and those bridged; and the frames that stand for the kept
    holes' lost mocap frames."""

    mocap: tuple[Hole, ...]
    force: tuple[Hole, ...]
    lost: np.ndarray            # (T,) bool, on the regular frame axis: a kept hole's frame
    bridged_mocap: tuple[Hole, ...] = ()
    bridged_force: tuple[Hole, ...] = ()


def session_holes(raw: RawSession, max_gap_s: float) -> tuple[RawSession, SessionHoles]:
    """The session on a regular mocap frame axis and a bridged force log, and its holes; a
    short mocap hole is bridged only where the gap filler fills ``max_gap_s``.

    Jitter in either stream is bad input (:func:`core.holes.find_holes`)."""
    mk = raw.markers
    mocap = find_holes(mk.time_ns, mk.source, "mocap frames")
    short_mocap = [h for h in mocap.holes if bridgeable(h) and
                   h.lost * h.period_ns * 1e-9 <= max_gap_s + 1e-9]
    markers, lost = regular_frames(mk, mocap, short_mocap)
    force_timing = find_holes(raw.force.time_ns, raw.force.source, "force samples")
    short_force = [h for h in force_timing.holes if bridgeable(h)]
    holes = SessionHoles(tuple(h for h in mocap.holes if h not in short_mocap),
                         tuple(h for h in force_timing.holes if h not in short_force), lost,
                         tuple(short_mocap), tuple(short_force))
    return replace(raw, markers=markers, force=bridge(raw.force, short_force)), holes


def bridgeable(hole: Hole) -> bool:
    """A hole of at most :data:`BRIDGED` lost samples, a whole number of periods long."""
    return hole.lost <= BRIDGED and hole.whole


def regular_frames(markers: MarkerSeries, timing: Timing, bridged: list[Hole] | None = None
                   ) -> tuple[MarkerSeries, np.ndarray]:
    """``markers`` with a frame of NaN markers for each frame a hole lost, at the times the
    frames would have had (a pause that is no whole number of frames ends on the next real
    frame); and which frames are a kept hole's (every hole's but the ``bridged`` ones, which
    the gap filler may fill)."""
    if not timing.holes:
        return markers, np.zeros(markers.frames, bool)
    bridged = bridged or []
    times, index, long_hole = [], [], []
    start = 0
    for h in timing.holes:
        fill = h.start_ns + np.round(np.arange(1, h.lost + 1) * h.period_ns).astype(np.int64)
        fill = fill[fill < h.stop_ns]
        times += [markers.time_ns[start:h.index], fill]
        index += [np.arange(start, h.index), np.full(len(fill), -1)]
        long_hole += [np.zeros(h.index - start, bool), np.full(len(fill), h not in bridged)]
        start = h.index
    times.append(markers.time_ns[start:])
    index.append(np.arange(start, markers.frames))
    long_hole.append(np.zeros(markers.frames - start, bool))
    seen = np.concatenate(index) >= 0
    positions = np.full((len(seen), *markers.positions.shape[1:]), np.nan)
    positions[seen] = markers.positions
    residuals = None
    if markers.residuals is not None:
        residuals = np.full((len(seen), markers.residuals.shape[1]), np.nan)
        residuals[seen] = markers.residuals
    return replace(markers, time_ns=np.concatenate(times), positions=positions,
                   residuals=residuals), np.concatenate(long_hole)


def bridge(force: ForceSeries, short: list[Hole]) -> ForceSeries:
    """The force log with each of the ``short`` holes (:func:`bridgeable`) filled by a
    straight line between its neighbours (values and trigger); other holes stay jumps."""
    if not short:
        return force
    t = force.time_ns
    new_t = np.concatenate([h.start_ns + np.round(np.arange(1, h.lost + 1) * h.period_ns)
                            .astype(np.int64) for h in short])
    time_ns = np.sort(np.concatenate([t, new_t]))
    values = np.stack([np.interp(time_ns, t, c) for c in force.values.T], axis=1)
    trigger = None if force.trigger is None else np.interp(time_ns, t, force.trigger)
    return replace(force, time_ns=time_ns, values=values, trigger=trigger)


@dataclass
class HoleSpan:
    """One hole on the mocap's frame axis: its stream, file, the hole, the frames it reaches
    (its own lost frames, or the frames whose force the resampler read from it) and the
    presses it cost."""

    stream: str                 # "mocap" or "force"
    source: str
    hole: Hole
    frames: np.ndarray          # (T,) bool
    at_s: float                 # where it starts on the mocap clock (s)
    bridged: bool = False       # bridged: it reaches no frame and costs no press
    presses: list[Press] = field(default_factory=list)

    @property
    def unit(self) -> str:
        return "frames" if self.stream == "mocap" else "samples"


def hole_spans(holes: SessionHoles, raw: RawSession, t_log_s: np.ndarray, reach_s: float
               ) -> list[HoleSpan]:
    """Every hole of both streams with the mocap frames it reaches: a mocap hole its lost
    frames; a force hole the frames whose logger time ``t_log_s`` lies in it or within the
    resampler's ``reach_s`` of it; a bridged hole none."""
    t_m = raw.markers.time_ns
    none = np.zeros(len(t_m), bool)
    spans = [HoleSpan("mocap", raw.markers.source, h,
                      none if bridged else holes.lost & (t_m > h.start_ns) & (t_m < h.stop_ns),
                      h.start_ns * 1e-9, bridged)
             for bridged, group in ((False, holes.mocap), (True, holes.bridged_mocap))
             for h in group]
    ok = np.isfinite(t_log_s)
    for bridged, group in ((False, holes.force), (True, holes.bridged_force)):
        for h in group:
            lo, hi = h.start_ns * 1e-9 - reach_s, h.stop_ns * 1e-9 + reach_s
            near = none if bridged else ok & (t_log_s >= lo) & (t_log_s <= hi)
            at = float(np.interp(h.start_ns * 1e-9, t_log_s[ok], t_m[ok] * 1e-9))
            spans.append(HoleSpan("force", raw.force.source, h, near, at, bridged))
    return sorted(spans, key=lambda s: s.at_s)


def touch_reach(rate_hz: float, p: SyncParams) -> int:
    """Frames a hole reaches into a press's record: sync's margin (every frame its states are
    read from, the rest before contact included), and at least half the tip filter's length
    (what the filter spreads a hole's edge over)."""
    margin = int(round(p.margin_s * rate_hz))
    if p.tip_cutoff_hz <= 0 or p.tip_cutoff_hz >= 0.25 * rate_hz:
        return max(margin, 1)
    return max(margin, len(smoothing_taps(rate_hz, p.tip_cutoff_hz)) // 2, 1)


def leave_out_touched(presses: list[Press], spans: list[HoleSpan], reach: int) -> list[Press]:
    """The presses no hole touches: none of the frames a hole reaches lies in a press's
    loaded span widened by ``reach`` frames (:func:`touch_reach`). Each span keeps the
    presses it cost."""
    kept = []
    for pr in presses:
        lo, hi = max(pr.onset - reach, 0), pr.release + reach
        hit = [s for s in spans if s.frames[lo:hi].any()]
        for s in hit:
            s.presses.append(pr)
        if not hit:
            kept.append(pr)
    return kept


def hole_line(span: HoleSpan, time_ns: np.ndarray, depth: np.ndarray,
              found: Sequence[Press] = (), reach: int = 0) -> str:
    """One warning line: the file, the hole (on its stream's clock, and on the mocap's for a
    force hole), and what it cost: the presses left out, or a press the force hole swallowed
    whole, seen by the tip's ``depth`` below the surface away from every ``found`` press
    (widened by ``reach`` frames)."""
    what = "mocap frames" if span.stream == "mocap" else "force samples"
    where = "" if span.stream == "mocap" else \
        f" of the log ({span.at_s:.3f} s on the mocap clock)"
    head = f"{span.source}: {span.hole.describe(what, span.unit)}{where}"
    if span.bridged:
        return (f"{head}: bridged by a straight line (at most {BRIDGED} {span.unit}); no "
                "press left out")
    cost = "; ".join(f"the press at {_span_s(pr, time_ns)}"
                     f"{f' (location {pr.location})' if pr.location >= 0 else ''} left out"
                     for pr in span.presses)
    if not cost:
        away = span.frames.copy()
        for pr in found:
            away[max(pr.onset - reach, 0):pr.release + reach] = False
        deepest = np.nanmax(depth[away], initial=-np.inf)
        cost = (f"the tip pressed {deepest * 1e3:.1f} mm deep during it: that press is lost"
                if deepest > PRESSING_M else "no press touched")
    return f"{head}: {cost}"


def hole_record(span: HoleSpan, time_ns: np.ndarray) -> dict[str, Any]:
    """A hole as JSON values for the synced file (times on the mocap clock, s, but
    ``after_s``, on the stream's own)."""
    frames = np.flatnonzero(span.frames)
    return {"stream": span.stream, "source": span.source, "lost": span.hole.lost,
            "length_s": span.hole.length_s, "bridged": span.bridged,
            "after_s": span.hole.start_ns * 1e-9, "at_s": span.at_s,
            "frames": [int(frames[0]), int(frames[-1]) + 1] if frames.size else None,
            "presses_left_out": [[float(time_ns[pr.onset] * 1e-9),
                                  float(time_ns[pr.release - 1] * 1e-9)]
                                 for pr in span.presses]}


def _span_s(pr: Press, time_ns: np.ndarray) -> str:
    return f"{time_ns[pr.onset] * 1e-9:.2f}-{time_ns[pr.release - 1] * 1e-9:.2f} s"

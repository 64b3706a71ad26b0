"""Holes in a session's streams: found, named, and kept out of every state (sync's first step).

A hole is a stretch of samples a stream never recorded (:mod:`core.holes`: found from the
stream's own clock; jitter stays bad input). Sync never interpolates across one:

- the mocap's lost frames come back as frames with no marker in them (:func:`regular_frames`),
  so every later step keeps its uniform frame axis and sees the hole as missing data, flagged
  ``lost`` in the synced file's quality bits;
- the force log is resampled stretch by stretch (:mod:`sync.resample`); the frames whose force
  the resampler read from a hole's edge are flagged ``in_hole`` in the force bits;
- a hole of at most :data:`BRIDGED` lost samples (a real-time client that drops a frame under
  load, a DAQ that slips one sample) is bridged: a straight line between its neighbours for
  the force, the marker gap filler for the mocap, well below either stream's noise;
- a press whose loaded span, widened by the filters' reach, touches a hole is left out, after
  it has been given its location (so the other presses keep theirs), and said
  (:func:`touched`, :func:`hole_lines`).
"""

from __future__ import annotations

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
    """The holes of a session's two streams, each on its own clock (the force log's holes
    after bridging), and the frames that stand for lost mocap frames."""

    mocap: tuple[Hole, ...]
    force: tuple[Hole, ...]
    lost: np.ndarray            # (T,) bool, on the regular frame axis: a hole's frame


def session_holes(raw: RawSession) -> tuple[RawSession, SessionHoles]:
    """The session on a regular mocap frame axis and a bridged force log, and its holes.

    Jitter in either stream is bad input (:func:`core.holes.find_holes`)."""
    mk = raw.markers
    mocap = find_holes(mk.time_ns, mk.source, "mocap frames")
    markers, lost = regular_frames(mk, mocap)
    force_timing = find_holes(raw.force.time_ns, raw.force.source, "force samples")
    force = bridge(raw.force, force_timing)
    kept = tuple(h for h in force_timing.holes if h.lost > BRIDGED)
    holes = SessionHoles(tuple(h for h in mocap.holes if h.lost > BRIDGED), kept, lost)
    return replace(raw, markers=markers, force=force), holes


def regular_frames(markers: MarkerSeries, timing: Timing) -> tuple[MarkerSeries, np.ndarray]:
    """``markers`` with a frame of NaN markers for each frame a hole lost, at the times the
    frames would have had (a pause that is no whole number of frames ends on the next real
    frame); and which frames are a long hole's (more than :data:`BRIDGED` lost: never
    filled in)."""
    if not timing.holes:
        return markers, np.zeros(markers.frames, bool)
    times, index, long_hole = [], [], []
    start = 0
    for h in timing.holes:
        fill = h.start_ns + np.round(np.arange(1, h.lost + 1) * h.period_ns).astype(np.int64)
        fill = fill[fill < h.stop_ns]
        times += [markers.time_ns[start:h.index], fill]
        index += [np.arange(start, h.index), np.full(len(fill), -1)]
        long_hole += [np.zeros(h.index - start, bool), np.full(len(fill), h.lost > BRIDGED)]
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


def bridge(force: ForceSeries, timing: Timing) -> ForceSeries:
    """The force log with each hole of at most :data:`BRIDGED` lost samples filled by a
    straight line between its neighbours (values and trigger); longer holes stay jumps."""
    short = [h for h in timing.holes if h.lost <= BRIDGED and
             abs((h.stop_ns - h.start_ns) / h.period_ns - (h.lost + 1)) < 0.5]
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
    presses: list[Press] = field(default_factory=list)


def hole_spans(holes: SessionHoles, raw: RawSession, t_log_s: np.ndarray, reach_s: float
               ) -> list[HoleSpan]:
    """Every hole of both streams with the mocap frames it reaches: a mocap hole its lost
    frames; a force hole the frames whose logger time ``t_log_s`` lies in it or within the
    resampler's ``reach_s`` of it."""
    t_m = raw.markers.time_ns
    spans = [HoleSpan("mocap", raw.markers.source, h,
                      holes.lost & (t_m > h.start_ns) & (t_m < h.stop_ns))
             for h in holes.mocap]
    for h in holes.force:
        near = (t_log_s >= h.start_ns * 1e-9 - reach_s) & (t_log_s <= h.stop_ns * 1e-9 + reach_s)
        spans.append(HoleSpan("force", raw.force.source, h, near))
    return spans


def touch_reach(rate_hz: float, p: SyncParams) -> int:
    """Frames a mocap hole reaches into the tip through its low-pass: half the filter's length
    (at least one frame)."""
    if p.tip_cutoff_hz <= 0 or p.tip_cutoff_hz >= 0.25 * rate_hz:
        return 1
    return max(len(smoothing_taps(rate_hz, p.tip_cutoff_hz)) // 2, 1)


def leave_out_touched(presses: list[Press], spans: list[HoleSpan], reach: int) -> list[Press]:
    """The presses no hole touches: none of the frames a hole reaches lies in a press's
    loaded span widened by ``reach`` frames (the tip's low-pass). Each span keeps the presses
    it cost."""
    kept = []
    for pr in presses:
        lo, hi = max(pr.onset - reach, 0), pr.release + reach
        hit = [s for s in spans if s.frames[lo:hi].any()]
        for s in hit:
            s.presses.append(pr)
        if not hit:
            kept.append(pr)
    return kept


def hole_line(span: HoleSpan, time_ns: np.ndarray, depth: np.ndarray) -> str:
    """One warning line: the file, the hole, and the presses it cost (a press the force
    hole swallowed whole is seen by the tip's ``depth`` alone)."""
    what = "mocap frames" if span.stream == "mocap" else "force samples"
    cost = "; ".join(f"the press at {_span_s(pr, time_ns)}"
                     f"{f' (location {pr.location})' if pr.location >= 0 else ''} left out"
                     for pr in span.presses)
    if not cost:
        deepest = np.nanmax(depth[span.frames], initial=-np.inf)
        cost = (f"the tip pressed {deepest * 1e3:.1f} mm deep during it: that press is lost"
                if deepest > PRESSING_M else "no press touched")
    return f"{span.source}: {span.hole.describe(what)}: {cost}"


def hole_record(span: HoleSpan, time_ns: np.ndarray) -> dict[str, Any]:
    """A hole as JSON values for the synced file (times on the mocap clock, s)."""
    frames = np.flatnonzero(span.frames)
    return {"stream": span.stream, "source": span.source, "lost": span.hole.lost,
            "length_s": span.hole.length_s,
            "after_s": span.hole.start_ns * 1e-9,          # on the stream's own clock
            "frames": [int(frames[0]), int(frames[-1]) + 1] if frames.size else None,
            "presses_left_out": [[float(time_ns[pr.onset] * 1e-9),
                                  float(time_ns[pr.release - 1] * 1e-9)]
                                 for pr in span.presses]}


def _span_s(pr: Press, time_ns: np.ndarray) -> str:
    return f"{time_ns[pr.onset] * 1e-9:.2f}-{time_ns[pr.release - 1] * 1e-9:.2f} s"

"""The sync stage's math: raw streams (ingest's MCAP) to one synchronised record per press.

Steps, each in its own module of :mod:`sync`:

1. the indenter cluster's shape and the tip offset from the pivot recording, the cluster's pose
   in every trial frame and the tip it carries, the last point (:mod:`sync.tip_track`);
2. short marker gaps filled, longer ones kept missing and flagged (:mod:`sync.gaps`); the tip
   track low-passed (zero phase) against the lever arm's noise (:mod:`sync.smooth`); the tip
   depth below the phantom's rest plane (:mod:`calib.rest_plane`);
3. the force tared from the unloaded start of the log, calibrated with the 6x6 matrix, and
   re-tared from the rest level next to every press (:mod:`sync.force_conditioning`);
4. the clock: one shared clock when the force came through the mocap's analog board,
   else trigger pulses when recorded, otherwise the tip depth against the force
   (:mod:`sync.clock_policy`; the calibration record says which policy applied and why; a
   data lock that fails its checks is refused);
5. the force low-passed and resampled at the mocap frame times mapped onto the logger's clock
   (:mod:`sync.resample`); frames beyond the sensor's rated load, or made of gauge voltages on
   the amplifier's rail, flagged in the force bits (:func:`force_bits`);
6. presses from contact onset to release, each with its location id and repeat number, cut
   out with a margin of unloaded frames on both sides; presses cut off by the end of either
   recording are left out (and counted) (:mod:`sync.presses`).

:func:`sync_session` returns everything in memory; :mod:`sync.sync_stage` reads its input and
writes it (:mod:`sync.synced_file`) and its view (:mod:`sync.sync_view`). Every bad input is
one :class:`BadInput` line.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from calib.force_tare import Tare
from calib.pivot import PivotResult
from calib.shape_registration import Registration
from core.errors import BadInput
from core.progress import warn
from core.series import RawSession
from data_schema.phantom import PhantomLayout
from data_schema.synced import FORCE_BITS, QUALITY_BITS
from sync.clock import IDENTITY, ClockFit
from sync.clock_policy import check_overlap, clock_reason, estimate_clock
from sync.force_conditioning import (
    ConditionedForce,
    beyond_rating,
    condition_force,
    near_samples,
    on_rail,
    output_rails,
)
from sync.gaps import LOST, MISSING, fill_gaps
from sync.holes import (
    HoleSpan,
    SessionHoles,
    hole_line,
    hole_record,
    hole_spans,
    leave_out_touched,
    session_holes,
    touch_reach,
)
from sync.presses import (
    Press,
    PressRecord,
    PressRule,
    assign_locations,
    cut_presses,
    segment_presses,
)
from sync.resample import antialias_taps, antialiased_interpolant
from sync.smooth import lowpass_track
from sync.surface import along_normals, rest_of
from sync.sync_params import SyncParams
from sync.tip_track import check_cluster, track_tip

POOR_FIT = np.uint8(QUALITY_BITS["poor_fit"])
TIP = "tip"


@dataclass
class SyncResult:
    """What sync produced: the presses, the calibration, and whole-session series to view."""

    name: str
    point_names: list[str]
    presses: list[PressRecord]
    clock: ClockFit
    pivot: PivotResult
    tare: Tare
    cluster_body: np.ndarray
    surface_point: np.ndarray
    surface_normal: np.ndarray
    location_centres: np.ndarray
    rate_hz: float
    calibration: dict[str, Any]
    presses_cut_off: int = 0         # presses left out: cut off by the end of a recording
    presses_in_holes: int = 0        # presses left out: touching a hole in a stream
    rail_samples: int = 0            # force log samples with a gauge on the amplifier's rail
    phantom: dict = field(default_factory=dict)   # the phantom's layout (data_schema.phantom)
    session: dict[str, np.ndarray] = field(default_factory=dict)   # full-length series
    holes: list[dict[str, Any]] = field(default_factory=list)   # each hole, as JSON values
    registration: Registration | None = None   # a curved phantom's markers on its shape


def sync_session(raw: RawSession, params: SyncParams | None = None) -> SyncResult:
    """Synchronise a raw session (see the module docstring for the steps)."""
    p = params or SyncParams()
    raw, holes = session_holes(raw, p.max_gap_s)
    mk = raw.markers
    rate = float(mk.rate_hz)
    t_m = mk.time_ns.astype(np.float64) * 1e-9
    phantom = mk.select(raw.phantom_markers)
    cluster = mk.select(raw.indenter_markers)

    track = track_tip(raw, p)
    pose = track.pose
    points, quality = session_points(t_m, phantom, track.tip, holes.lost, rate, p)
    quality[:, -1] |= np.where(pose.poor, POOR_FIT, 0).astype(np.uint8)
    layout = PhantomLayout.from_json(raw.phantom)
    surface = rest_of(phantom, cluster, track.tip, raw.phantom_markers, layout, mk.source)
    depth = surface.depth(points[:, -1])

    cf = condition_force(raw, p)
    force_at = antialiased_interpolant(cf.time_s, cf.wrench, rate, p.passband, cf.stretches)

    def magnitude_at(t: np.ndarray) -> np.ndarray:
        return np.linalg.norm(force_at(t)[:, :3], axis=1)

    clock, clock_note = estimate_clock(raw, p, t_m, depth, cf.time_s, magnitude_at)
    check_overlap(raw, clock, t_m, cf.time_s)

    t_log = clock.to_logger(t_m)
    on = frame_force(force_at, cf, raw, holes, t_log, p)
    rail = on_rail(raw)
    force_q = force_bits(on.sampled, beyond_rating(on.sampled, raw.calibration),
                         near_samples(cf.time_s, rail, t_log,
                                      _filter_reach_s(cf.time_s, rate, p.passband)),
                         on.in_force_hole)
    force, torque = on.sampled[:, :3], on.sampled[:, 3:]
    magnitude = on.magnitude

    found, cut_off = segment_presses(magnitude, rate, PressRule(p.detect_n, cf.contact))
    touch, touch_normal = surface.touches(points[:, -1], depth, found)
    loc_centres = place(found, touch, p.location_radius_m)
    reach = touch_reach(rate, p)
    presses = leave_out_touched(found, on.spans, reach)
    for span in on.spans:
        warn(hole_line(span, mk.time_ns, depth, found, reach))
    if not presses:
        raise BadInput(raw.force.source, _no_press(p, cut_off, len(found)))
    check_cluster(raw, pose, presses)
    series = {"time_ns": mk.time_ns, "points": points, "quality": quality, "force": force,
              "torque": torque, "force_magnitude": magnitude, "depth": depth,
              "force_quality": force_q}
    records = cut_presses(presses, series, int(round(p.margin_s * rate)))
    if surface.registration is not None:
        kept = [next(k for k, f in enumerate(found) if f is pr) for pr in presses]
        along_normals(records, touch[kept], touch_normal[kept])
    for rec in records:
        ends = rec.time_ns[[rec.press.onset, rec.press.release - 1]] * 1e-9
        rec.rest = cf.rest.at(clock.to_logger(ends))
    calibration = _calibration_record(raw, track.pivot, cf, clock, p, clock_note)
    calibration["force"].update(rail_v=output_rails(raw), rail_samples=int(rail.sum()))
    session = {"time_ns": mk.time_ns, "tip": points[:, -1], "depth": depth,
               "force_magnitude": magnitude, "cluster": cluster,
               "force_magnitude_unaligned": magnitude_at(IDENTITY.to_logger(t_m)),
               "quality": quality, "points": points, "force_quality": force_q,
               "hole": on.hole_frames}
    return SyncResult(
        name=raw.name, point_names=list(raw.phantom_markers) + [TIP], presses=records,
        clock=clock, pivot=track.pivot, tare=cf.tare, cluster_body=track.cluster_body,
        surface_point=surface.point, surface_normal=surface.normal, location_centres=loc_centres,
        rate_hz=rate, calibration=calibration, presses_cut_off=cut_off, session=session,
        rail_samples=int(rail.sum()), phantom=layout.as_json(), registration=surface.registration,
        holes=[hole_record(span, mk.time_ns) for span in on.spans],
        presses_in_holes=len(found) - len(presses),
    )


def session_points(t_m: np.ndarray, phantom: np.ndarray, tip: np.ndarray, lost: np.ndarray,
                   rate: float, p: SyncParams) -> tuple[np.ndarray, np.ndarray]:
    """The phantom markers and the tip (T, N + 1, 3) with short gaps filled, a hole's frames
    left empty (flagged ``lost``), the tip low-passed; and their quality bits."""
    points, quality = fill_gaps(t_m, np.concatenate([phantom, tip[:, None]], axis=1),
                                p.max_gap_s, never=lost)
    quality[lost] = MISSING | LOST
    points[:, -1] = lowpass_track(points[:, -1], rate, p.tip_cutoff_hz)
    return points, quality


@dataclass
class FrameForce:
    """The force resampled on the mocap frames, and where the holes of both streams reach."""

    sampled: np.ndarray          # (T, 6) Fx..Tz, sensor frame; NaN off the log and in its holes
    spans: list[HoleSpan]        # every hole, with the frames it reaches
    hole_frames: np.ndarray      # (T,) bool: a hole of either stream reaches the frame
    in_force_hole: np.ndarray    # (T,) bool: a hole of the force log does

    @property
    def magnitude(self) -> np.ndarray:
        """The force magnitude (T,), N."""
        return np.linalg.norm(self.sampled[:, :3], axis=1)


def frame_force(force_at: Callable[[np.ndarray], np.ndarray], cf: ConditionedForce,
                raw: RawSession, holes: SessionHoles, t_log: np.ndarray, p: SyncParams
                ) -> FrameForce:
    """The conditioned force at the frames' logger times ``t_log`` (s), and the frames each
    hole reaches: a mocap hole its lost frames, a force hole the frames resampled from it."""
    spans = hole_spans(holes, raw, t_log, _filter_reach_s(cf.time_s, raw.markers.rate_hz,
                                                          p.passband))
    in_force_hole = np.zeros(len(t_log), bool)
    for span in spans:
        if span.stream == "force":
            in_force_hole |= span.frames
    return FrameForce(force_at(t_log), spans, holes.lost | in_force_hole, in_force_hole)


def place(presses: list[Press], centres: np.ndarray, radius_m: float) -> np.ndarray:
    """Each press's location and repeat from its contact point (:func:`assign_locations`),
    set on the press; the locations' centres. Sync places every complete press, those a hole
    touched too: the others keep the ids they would have without the hole."""
    loc, rep, loc_centres = assign_locations(centres, radius_m)
    for pr, lo, re in zip(presses, loc, rep, strict=True):
        pr.location, pr.repeat = int(lo), int(re)
    return loc_centres


def _no_press(p: SyncParams, cut_off: int, in_holes: int) -> str:
    """Why no press is left (``in_holes`` complete ones a hole touched), in words."""
    why = [f"{cut_off} cut off by the end of a recording"] if cut_off else []
    why += [f"{in_holes} touching a hole"] if in_holes else []
    if not why:
        return f"no complete press found (force never rises above {p.detect_n:g} N)"
    return f"no complete press found ({' and '.join(why)} left out)"


def force_bits(sampled: np.ndarray, over: np.ndarray, saturated: np.ndarray,
               in_hole: np.ndarray | None = None) -> np.ndarray:
    """Each frame's force quality bits (:data:`FORCE_BITS`): outside the log (NaN, and not in
    a hole of it), beyond the rated range, made of gauge samples on the amplifier's rail, in
    or within the resampler's reach of a hole of the log."""
    hole = np.zeros(len(sampled), bool) if in_hole is None else np.asarray(in_hole, bool)
    q = np.where(np.isnan(sampled).any(axis=1) & ~hole, FORCE_BITS["outside_log"], 0)
    q |= np.where(over, FORCE_BITS["over_range"], 0)
    q |= np.where(saturated, FORCE_BITS["saturated"], 0)
    q |= np.where(hole, FORCE_BITS["in_hole"], 0)
    return q.astype(np.uint8)


def flagged_presses(presses: list[PressRecord], bit: str) -> tuple[int, int]:
    """How many presses have force bit ``bit`` between onset and release, and on how many
    frames in all."""
    frames = [int(((r.force_quality[r.press.onset:r.press.release] & FORCE_BITS[bit]) > 0)
                  .sum()) for r in presses]
    return sum(1 for n in frames if n), sum(frames)


def _filter_reach_s(t_log_s: np.ndarray, rate_hz: float, passband: float) -> float:
    """Half the resampling filter's length (s): how far a log sample reaches into the
    resampled force."""
    fs = 1.0 / float(np.median(np.diff(t_log_s)))         # holes aside
    return (len(antialias_taps(fs, rate_hz, passband)) // 2 + 1) / fs


def _calibration_record(raw: RawSession, pivot: PivotResult, cf: ConditionedForce,
                        clock: ClockFit, p: SyncParams, clock_note: str | None
                        ) -> dict[str, Any]:
    """What sync measured, with its uncertainty, as plain JSON values."""
    f, tare, rest = raw.force, cf.tare, cf.rest
    moved = np.linalg.norm(rest.level[:, :3], axis=1) if len(rest.time_s) else np.zeros(1)
    return {
        "tip": {"tip_body_m": pivot.tip_body.tolist(), "rms_m": pivot.rms,
                "n_poses": pivot.n_poses, "rotation_spread_deg": pivot.rotation_spread_deg,
                "pivot_lab_m": pivot.pivot_lab.tolist(),
                "source": None if raw.pivot is None else str(raw.pivot.source)},
        "force": {"kind": f.kind, "bias": tare.bias.tolist(), "units": list(f.units),
                  "noise": tare.noise.tolist(), "noise_force_n": cf.noise,
                  "tare_interval_s": [tare.start / f.rate_hz, tare.stop / f.rate_hz],
                  "matrix_source": None if raw.calibration is None else
                  str(raw.calibration.source), "source": str(f.source),
                  "retare_anchors": len(rest.time_s), "retare_max_n": float(moved.max())},
        "clock": {**clock.as_dict(), "note": clock_note,
                  "policy": clock.method, "why": clock_reason(raw, p, clock, clock_note)},
        "params": asdict(p),
    }


"""``pipeline sync``: raw streams (ingest's MCAP) to one synchronised record per press.

Steps, each a function of :mod:`calib` or :mod:`pipeline.presses`:

1. the indenter cluster's shape and the tip offset from the pivot recording (pivot calibration);
2. the cluster's pose in every trial frame (3 of 4 markers suffice; robustly reweighted; poor
   or ill-conditioned fits flagged and dropped) and the tip, the 26th point;
3. short marker gaps filled, longer ones kept missing and flagged; the tip track low-passed
   (zero phase) against the lever arm's noise; the tip depth below the phantom's rest plane;
4. the force tare from the unloaded start of the log and the 6x6 calibration matrix, then a
   re-tare from the rest level next to every press (bias creep, tool weight);
5. the clock: trigger pulses when recorded, otherwise the tip depth against the force;
6. the force low-passed and resampled at the mocap frame times mapped onto the logger's clock;
7. presses from contact onset to release, each with its location id and repeat number, cut
   out with a margin of unloaded frames on both sides; presses cut off by the end of either
   recording are left out (and counted).

Nothing is written unless everything succeeds; every bad input is one :class:`BadInput` line.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from calib.clock import (
    IDENTITY,
    ClockFit,
    clock_from_data,
    contact_lag,
    match_trigger,
    rising_edges,
    stamp_resolution_s,
)
from calib.force import RestBaseline, Tare, apply_calibration, rest_baseline, unloaded_start
from calib.gaps import MISSING, fill_gaps
from calib.phantom_frame import rest_plane
from calib.pivot import PivotResult, pivot_calibrate
from calib.resample import antialiased_interpolant
from calib.rigid import RigidFit, cluster_reference, fit_rigid
from calib.smooth import lowpass_track
from core.atomic import atomic_outputs
from core.errors import BadInput
from core.provenance import make_provenance
from core.series import RawSession
from data_schema.hdf5 import validate_h5
from data_schema.synced import FORCE_BITS, QUALITY_BITS, SYNCED
from pipeline.presses import Press, assign_locations, segment_presses

POOR_FIT = np.uint8(QUALITY_BITS["poor_fit"])
TIP = "tip"
MIN_PULSES = 3                   # trigger edges and events the trigger clock needs
MIN_TRACKED = 0.05               # least fraction of frames with a usable indenter pose


@dataclass
class SyncParams:
    """Every setting of the sync stage (stored in the output's provenance)."""

    clock: str = "auto"              # auto (trigger when recorded, else data) | trigger | data
    max_gap_s: float = 0.020         # longest marker gap filled
    margin_s: float = 0.5            # unloaded frames kept before onset and after release
    detect_n: float = 0.5            # a press must rise above this force
    contact_n: float = 0.05          # contact level (raised to 5 noise widths if need be)
    location_radius_m: float = 0.010  # presses closer than this share a location
    max_offset_s: float = 30.0       # data-driven clock: largest clock offset searched
    passband: float = 0.8            # resampler flat to this fraction of the mocap Nyquist
    max_fit_rms_m: float = 1.0e-3    # rigid fits with a larger residual are poor
    robust_scale_m: float = 0.3e-3   # Cauchy reweighting of the cluster fit (0: plain LS)
    tip_cutoff_hz: float = 15.0      # zero-phase low-pass of the tip track (0: off)
    min_pivot_rotation_deg: float = 5.0
    min_correlation: float = 0.5     # data-driven clock: force must follow the depth this well
    retare: bool = True              # re-tare from the rest next to every press (False: start)


@dataclass
class PressRecord:
    """One press, cut out with its margins, on the mocap clock."""

    press: Press                     # indices into this record's frames
    time_ns: np.ndarray
    points: np.ndarray
    force: np.ndarray
    torque: np.ndarray
    force_magnitude: np.ndarray
    depth: np.ndarray
    quality: np.ndarray
    force_quality: np.ndarray
    rest: np.ndarray                 # (2, 6) re-tare removed at onset and at release (N, N*m)


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
    session: dict[str, np.ndarray] = field(default_factory=dict)   # full-length series


def sync_session(raw: RawSession, params: SyncParams | None = None) -> SyncResult:
    """Synchronise a raw session (see the module docstring for the steps)."""
    p = params or SyncParams()
    check_params(p)
    mk = raw.markers
    rate = float(mk.rate_hz)
    t_m = mk.time_ns.astype(np.float64) * 1e-9
    phantom = mk.select(raw.phantom_markers)
    cluster = mk.select(raw.indenter_markers)

    ref, pivot = _pivot(raw, p)
    pose = fit_rigid(ref, cluster, max_rms=p.max_fit_rms_m, robust_scale=p.robust_scale_m)
    _check_tracked(raw, pose)
    tip = pose.apply(pivot.tip_body)
    tip[pose.poor] = np.nan
    points, quality = fill_gaps(t_m, np.concatenate([phantom, tip[:, None]], axis=1),
                                p.max_gap_s)
    points[:, -1] = lowpass_track(points[:, -1], rate, p.tip_cutoff_hz)
    quality[:, -1] |= np.where(pose.poor, POOR_FIT, 0).astype(np.uint8)
    shaft = _mean_seen(cluster) - tip
    surface_point, normal = rest_plane(phantom, shaft, mk.source)
    depth = (surface_point - points[:, -1]) @ normal

    tare, wrench, noise = _force(raw, p)
    contact = max(p.contact_n, 5 * noise)
    t_f = _force_times(raw)
    rest = (rest_baseline(t_f, wrench, contact, max(contact, 0.5 * p.detect_n)) if p.retare
            else RestBaseline(np.empty(0), np.empty((0, wrench.shape[1]))))
    wrench = wrench - rest.at(t_f)
    force_at = antialiased_interpolant(t_f, wrench, rate, p.passband)

    def magnitude_at(t: np.ndarray) -> np.ndarray:
        return np.linalg.norm(force_at(t)[:, :3], axis=1)

    clock, clock_note = estimate_clock(raw, p, t_m, depth, t_f, magnitude_at)
    _check_overlap(raw, clock, t_m, t_f)

    sampled = force_at(clock.to_logger(t_m))
    force_q = np.where(np.isnan(sampled).any(axis=1), FORCE_BITS["outside_log"], 0)
    over = _over_range(raw, sampled)
    force_q = (force_q | np.where(over, FORCE_BITS["over_range"], 0)).astype(np.uint8)
    force, torque = sampled[:, :3], sampled[:, 3:]
    magnitude = np.linalg.norm(force, axis=1)

    presses, cut_off = segment_presses(magnitude, rate, p.detect_n, contact)
    if not presses:
        whole = "" if not cut_off else (f"; {cut_off} cut off by the end of a recording "
                                         "left out")
        raise BadInput(raw.force.source, f"no complete press found (force never rises above "
                                         f"{p.detect_n:g} N{whole})")
    _check_cluster(raw, pose, presses)
    centres = _contact_points(points[:, -1], presses, surface_point, normal)
    loc, rep, loc_centres = assign_locations(centres, p.location_radius_m)
    for pr, lo, re in zip(presses, loc, rep, strict=True):
        pr.location, pr.repeat = int(lo), int(re)
    series = {"time_ns": mk.time_ns, "points": points, "quality": quality, "force": force,
              "torque": torque, "force_magnitude": magnitude, "depth": depth,
              "force_quality": force_q}
    records = cut_presses(presses, series, int(round(p.margin_s * rate)))
    for rec in records:
        ends = rec.time_ns[[rec.press.onset, rec.press.release - 1]] * 1e-9
        rec.rest = rest.at(clock.to_logger(ends))
    calibration = _calibration_record(raw, pivot, tare, clock, p, noise, rest, clock_note)
    session = {"time_ns": mk.time_ns, "tip": points[:, -1], "depth": depth,
               "force_magnitude": magnitude, "cluster": cluster,
               "force_magnitude_unaligned": magnitude_at(IDENTITY.to_logger(t_m)),
               "quality": quality, "points": points}
    return SyncResult(
        name=raw.name, point_names=list(raw.phantom_markers) + [TIP], presses=records,
        clock=clock, pivot=pivot, tare=tare, cluster_body=ref, surface_point=surface_point,
        surface_normal=normal, location_centres=loc_centres, rate_hz=rate,
        calibration=calibration, presses_cut_off=cut_off, session=session,
    )


def check_params(p: SyncParams) -> None:
    """Refuse settings outside their meaning (the CLI checks its options the same way)."""
    if p.clock not in ("auto", "trigger", "data"):
        raise BadInput(None, f"--clock must be auto, trigger or data, got {p.clock!r}")
    for name, value, strict in (("max_gap_s", p.max_gap_s, False),
                                ("margin_s", p.margin_s, False),
                                ("location_radius_m", p.location_radius_m, True),
                                ("detect_n", p.detect_n, True), ("contact_n", p.contact_n, True),
                                ("max_offset_s", p.max_offset_s, True),
                                ("max_fit_rms_m", p.max_fit_rms_m, True),
                                ("robust_scale_m", p.robust_scale_m, False),
                                ("tip_cutoff_hz", p.tip_cutoff_hz, False)):
        if not (value > 0 if strict else value >= 0):
            raise BadInput(None, f"sync parameter {name} must be "
                                 f"{'positive' if strict else 'zero or more'}, got {value:g}")
    if not 0 < p.passband < 1:
        raise BadInput(None, f"sync parameter passband must be in (0, 1), got {p.passband:g}")


# --- steps ------------------------------------------------------------------------------------


def _pivot(raw: RawSession, p: SyncParams) -> tuple[np.ndarray, PivotResult]:
    if raw.pivot is None:
        raise BadInput(raw.markers.source, "no pivot recording in the session: the tip offset "
                                           "of the indenter is unknown")
    cluster = raw.pivot.select(raw.indenter_markers)
    ref = cluster_reference(cluster, raw.pivot.source)
    fit = fit_rigid(ref, cluster, max_rms=p.max_fit_rms_m, robust_scale=p.robust_scale_m)
    good = fit.valid & ~fit.poor
    res = pivot_calibrate(fit.rotation[good], fit.translation[good], raw.pivot.source,
                          p.min_pivot_rotation_deg)
    return ref, res


def _mean_seen(points: np.ndarray) -> np.ndarray:
    """Mean over axis 1 of (T, M, 3) points, NaN ones left out (NaN where none is seen)."""
    seen = np.isfinite(points).all(axis=2)
    n = seen.sum(axis=1)[:, None]
    total = np.where(seen[..., None], points, 0.0).sum(axis=1)
    return np.where(n > 0, total / np.maximum(n, 1), np.nan)


def _force(raw: RawSession, p: SyncParams) -> tuple[Tare, np.ndarray, float]:
    """Tare and calibrate the log: (tare, wrench, noise of the tared force in N).

    A start under load passes the tare's flatness test when it is held steady, but then the
    force does not come back to zero after the first press: the rest it returns to is
    compared with the contact level (5 noise widths at least), well above the creep of the
    bias over one press cycle.
    """
    f = raw.force
    if f.kind == "gauge" and raw.calibration is None:
        raise BadInput(f.source, "gauge voltages but no ATI calibration in the session")
    if not np.isfinite(f.values).all():
        bad = int(np.flatnonzero(~np.isfinite(f.values).all(axis=1))[0])
        raise BadInput(f.source, "force log has missing samples", where=f"sample {bad}")
    tare = unloaded_start(f.values, f.rate_hz, f.source)
    matrix = raw.calibration.matrix if f.kind == "gauge" else None
    wrench = apply_calibration(f.values, tare.bias, matrix)
    noise = _noise_level(wrench, tare)
    contact = max(p.contact_n, 5 * noise)
    rest = rest_after_first_press(np.linalg.norm(wrench[:, :3], axis=1), p.detect_n)
    if rest is not None and rest > contact:
        raise BadInput(f.source, f"force log did not start unloaded: after taring its start, "
                                 f"the force between presses is {rest:.2f} N, not 0 (more "
                                 f"than the contact level {contact:.2f} N; no unloaded "
                                 "interval to tare from)", where="sample 0")
    return tare, wrench, noise


def rest_after_first_press(magnitude: np.ndarray, detect_n: float) -> float | None:
    """Median force magnitude between the first press's release and the next press.

    The first press is the first rise above ``detect_n``; it is released where the magnitude
    falls below half of that, and the rest lasts until the next rise above ``detect_n`` (or
    the end). None when nothing rises above ``detect_n`` or the first press never ends.
    """
    m = np.asarray(magnitude, float)
    above = np.flatnonzero(m > detect_n)
    if above.size == 0:
        return None
    below = np.flatnonzero(m[above[0]:] < 0.5 * detect_n)
    if below.size == 0:
        return None
    start = int(above[0] + below[0])
    again = np.flatnonzero(m[start:] > detect_n)
    stop = start + int(again[0]) if again.size else len(m)
    return float(np.median(m[start:stop]))


def _force_times(raw: RawSession) -> np.ndarray:
    """Logger times (s); the resampler needs a uniform grid, so jitter is bad input."""
    t = raw.force.time_ns.astype(np.float64) * 1e-9
    step = np.diff(t)
    nominal = np.median(step)
    jitter = np.abs(step - nominal).max() if len(step) else 0.0
    if len(t) < 64 or jitter > 0.1 * nominal:
        raise BadInput(raw.force.source, "force log is too short or not uniformly sampled "
                                         f"(largest step deviation {jitter * 1e3:.3f} ms)")
    return t


def estimate_clock(raw: RawSession, p: SyncParams, t_m: np.ndarray, depth: np.ndarray,
                   t_f: np.ndarray, magnitude_at: Any) -> tuple[ClockFit, str | None]:
    """The logger-vs-mocap clock: trigger pulses when recorded (and asked for), else data.

    With ``--clock auto`` a trigger channel that shows fewer than :data:`MIN_PULSES` edges
    (a dead or unplugged line) or a mocap file with fewer trigger events falls back to the
    data; the second value then says why (None otherwise).
    """
    edges, events = _trigger(raw)
    if p.clock == "trigger" and edges is None:
        raise BadInput(raw.force.source, "--clock trigger, but the session has no trigger "
                                         "channel with matching mocap events")
    note = None
    if p.clock == "auto" and edges is not None and min(len(edges), len(events)) < MIN_PULSES:
        note = (f"trigger unusable ({len(edges)} pulse edges in the force log, {len(events)} "
                "trigger events in the mocap file): clock from the data")
        edges = None
    if p.clock == "data" or edges is None:
        return _data_clock(raw, p, t_m, depth, t_f, magnitude_at), note
    # both stamps are rounded: the logger's edge to its sample, the EVENT to its decimals
    step = np.median(np.diff(t_f))
    sd = float(np.sqrt((step**2 + stamp_resolution_s(np.round(events * 1e9)) ** 2) / 12))
    try:
        return match_trigger(edges, events, raw.force.source, timing_sd_s=sd,
                             min_pulses=MIN_PULSES), None
    except BadInput as e:
        if "ambiguous" not in e.what:
            raise
    prior = _data_clock(raw, p, t_m, depth, t_f, magnitude_at)
    return match_trigger(edges, events, raw.force.source, prior=prior, timing_sd_s=sd,
                         min_pulses=MIN_PULSES), None


def _trigger(raw: RawSession) -> tuple[np.ndarray | None, np.ndarray | None]:
    f = raw.force
    if f.trigger is None or raw.trigger_event is None:
        return None, None
    events = np.array([t for label, t in raw.markers.events if label == raw.trigger_event],
                      float) * 1e-9
    if events.size == 0:
        return None, None
    return rising_edges(f.time_ns.astype(np.float64) * 1e-9, f.trigger), events


def _data_clock(raw: RawSession, p: SyncParams, t_m: np.ndarray, depth: np.ndarray,
                t_f: np.ndarray, magnitude_at: Any) -> ClockFit:
    src = raw.markers.source
    if np.isfinite(depth).sum() < 100:
        raise BadInput(src, "clock: the tip is tracked in too few frames to align the force")
    try:
        lag0 = contact_lag(t_m, depth, magnitude_at, (t_f[0], t_f[-1]), p.max_offset_s)
    except ValueError:
        raise BadInput(src, f"clock: force log and mocap recording do not overlap in time "
                            f"for any clock offset within +-{p.max_offset_s:g} s") from None
    mag = magnitude_at(t_m + lag0)
    loaded, _ = segment_presses(mag, raw.markers.rate_hz, p.detect_n, max(p.contact_n, 0.1))
    windows = [(t_m[pr.onset:pr.release], depth[pr.onset:pr.release]) for pr in loaded]
    fit = clock_from_data(windows, magnitude_at, lag0, src)
    f = magnitude_at(fit.to_logger(t_m))
    ok = np.isfinite(f) & np.isfinite(depth)
    r = np.corrcoef(f[ok], depth[ok])[0, 1] if ok.sum() > 10 else 0.0
    if not r >= p.min_correlation:
        raise BadInput(src, f"clock: the force does not follow the tip motion at any clock "
                            f"offset within +-{p.max_offset_s:g} s (best correlation {r:.2f}); "
                            "the streams may not overlap in time")
    return fit


def _check_overlap(raw: RawSession, clock: ClockFit, t_m: np.ndarray, t_f: np.ndarray) -> None:
    lo = max(clock.to_logger(t_m[0]), t_f[0])
    hi = min(clock.to_logger(t_m[-1]), t_f[-1])
    if hi - lo < 1.0:
        raise BadInput(raw.force.source, f"force log and mocap recording do not overlap in "
                                         f"time (common span {max(hi - lo, 0):.3f} s on the "
                                         f"{clock.method} clock)")


def _over_range(raw: RawSession, sampled: np.ndarray) -> np.ndarray:
    if raw.calibration is None:
        return np.zeros(len(sampled), bool)
    limit = np.asarray(raw.calibration.max_load, float)
    with np.errstate(invalid="ignore"):
        return (np.abs(sampled) > limit).any(axis=1)


def _noise_level(wrench: np.ndarray, tare: Tare) -> float:
    """Standard deviation of the force magnitude's components while unloaded (N)."""
    return float(np.max(wrench[tare.start:tare.stop, :3].std(axis=0)))


def _check_tracked(raw: RawSession, pose: RigidFit) -> None:
    """Refuse a session whose indenter has a usable pose in almost no frame."""
    usable = pose.valid & ~pose.poor
    if usable.mean() < MIN_TRACKED:
        raise BadInput(raw.markers.source, f"the indenter has a usable pose in only "
                                           f"{int(usable.sum())} of {len(usable)} frames "
                                           f"({int(pose.poor.sum())} fits poor): are its "
                                           "markers labelled as in the pivot recording?")


def _check_cluster(raw: RawSession, pose: RigidFit, presses: list[Press]) -> None:
    """Every press needs a usable pose (3 markers seen and a fit that is not poor)."""
    for k, pr in enumerate(presses):
        span = slice(pr.onset, pr.release)
        if (pose.valid[span] & ~pose.poor[span]).any():
            continue
        what = ("fewer than 3 indenter markers seen through the whole press" if
                not pose.valid[span].any() else "every indenter fit through the whole press "
                "is poor (markers mislabelled, or a ghost marker?)")
        raise BadInput(raw.markers.source, f"press {k}: {what}, so the tip is unknown",
                       where=f"frames {pr.onset}-{pr.release - 1}")


def _contact_points(tip: np.ndarray, presses: list[Press], point: np.ndarray,
                    normal: np.ndarray, frames: int = 10) -> np.ndarray:
    """Where each press touched: the tip over its first loaded frames, on the rest plane.

    The onset, not the peak: a tilted press slides the tip sideways as it sinks in.
    """
    out = np.full((len(presses), 3), np.nan)
    for k, pr in enumerate(presses):
        seg = tip[pr.onset:min(pr.onset + frames, pr.release)]
        seg = seg[np.isfinite(seg).all(axis=1)]
        if len(seg) == 0:
            seg = tip[pr.onset:pr.release]
            seg = seg[np.isfinite(seg).all(axis=1)][:frames]
        if len(seg):
            c = np.median(seg, axis=0)
            out[k] = c - ((c - point) @ normal) * normal
    return out


def cut_presses(presses: list[Press], series: dict[str, np.ndarray], margin: int
                ) -> list[PressRecord]:
    """Each press with ``margin`` frames either side (never into a neighbouring press)."""
    out = []
    n = len(series["time_ns"])
    for k, pr in enumerate(presses):
        lo = max(pr.onset - margin, presses[k - 1].release if k else 0, 0)
        hi = min(pr.release + margin, presses[k + 1].onset if k + 1 < len(presses) else n)
        local = Press(pr.onset - lo, pr.release - lo, pr.peak - lo, pr.location, pr.repeat)
        out.append(PressRecord(local, **{key: v[lo:hi] for key, v in series.items()},
                               rest=np.zeros((2, 6))))
    return out


def _calibration_record(raw: RawSession, pivot: PivotResult, tare: Tare, clock: ClockFit,
                        p: SyncParams, noise: float, rest: RestBaseline,
                        clock_note: str | None) -> dict[str, Any]:
    f = raw.force
    moved = np.linalg.norm(rest.level[:, :3], axis=1) if len(rest.time_s) else np.zeros(1)
    return {
        "tip": {"tip_body_m": pivot.tip_body.tolist(), "rms_m": pivot.rms,
                "n_poses": pivot.n_poses, "rotation_spread_deg": pivot.rotation_spread_deg,
                "pivot_lab_m": pivot.pivot_lab.tolist(),
                "source": None if raw.pivot is None else str(raw.pivot.source)},
        "force": {"kind": f.kind, "bias": tare.bias.tolist(), "units": list(f.units),
                  "noise": tare.noise.tolist(), "noise_force_n": noise,
                  "tare_interval_s": [tare.start / f.rate_hz, tare.stop / f.rate_hz],
                  "matrix_source": None if raw.calibration is None else
                  str(raw.calibration.source), "source": str(f.source),
                  "retare_anchors": len(rest.time_s), "retare_max_n": float(moved.max())},
        "clock": {**clock.as_dict(), "note": clock_note},
        "params": asdict(p),
    }


# --- output -----------------------------------------------------------------------------------


def write_synced(path: str | Path, result: SyncResult, provenance: dict[str, Any],
                 source: str) -> None:
    """Write ``result`` to ``path`` in the :data:`data_schema.synced.SYNCED` layout."""
    with h5py.File(path, "w") as h:
        h.attrs.update({
            "schema": SYNCED.name, "schema_version": SYNCED.version,
            "provenance": json.dumps(provenance), "source": source,
            "calibration": json.dumps(result.calibration),
            "quality_bits": json.dumps(QUALITY_BITS), "force_bits": json.dumps(FORCE_BITS),
            "units_length": "m", "units_force": "N", "units_time": "ns",
            "rate_hz": result.rate_hz, "name": result.name,
        })
        h.create_dataset("point_names", data=np.array(result.point_names, dtype=object),
                         dtype=h5py.string_dtype())
        cal = h.create_group("calibration")
        _put(cal, "cluster_body", result.cluster_body, "m")
        _put(cal, "tip_body", result.pivot.tip_body, "m")
        _put(cal, "force_bias", result.tare.bias, ",".join(result.calibration["force"]["units"]))
        _put(cal, "surface_point", result.surface_point, "m")
        _put(cal, "surface_normal", result.surface_normal, "1")
        c = result.clock
        cal.attrs.update({
            "clock_method": c.method, "clock_offset_s": c.offset_s,
            "clock_offset_sd_s": c.offset_sd_s, "clock_drift_ppm": c.drift_ppm,
            "clock_drift_sd_ppm": c.drift_sd_ppm, "clock_rms_s": c.rms_s, "clock_n": c.n,
            "tip_rms_m": result.pivot.rms,
            "tip_rotation_spread_deg": result.pivot.rotation_spread_deg,
        })
        _put(h.require_group("locations"), "centre", result.location_centres.reshape(-1, 3), "m")
        presses = h.create_group("presses")
        presses.attrs["cut_off"] = result.presses_cut_off
        for k, rec in enumerate(result.presses):
            g = presses.create_group(f"{k:03d}")
            _put(g, "time_ns", rec.time_ns.astype(np.int64), "ns")
            _put(g, "points", rec.points, "m", compress=True)
            _put(g, "force", rec.force, "N")
            _put(g, "torque", rec.torque, "N*m")
            _put(g, "force_magnitude", rec.force_magnitude, "N")
            _put(g, "depth", rec.depth, "m")
            _put(g, "quality", rec.quality.astype(np.uint8), None, compress=True)
            _put(g, "force_quality", rec.force_quality.astype(np.uint8), None)
            pr = rec.press
            g.attrs.update({
                "location": pr.location, "repeat": pr.repeat, "onset_index": pr.onset,
                "peak_index": pr.peak, "release_index": pr.release,
                "onset_ns": int(rec.time_ns[pr.onset]),
                "release_ns": int(rec.time_ns[pr.release - 1]),
                "rest_force_n": rec.rest[:, :3], "rest_torque_nm": rec.rest[:, 3:],
                "points_missing_throughout": np.flatnonzero(
                    (rec.quality[pr.onset:pr.release] & MISSING).all(axis=0)).astype(np.int64),
            })


def _put(group: h5py.Group, name: str, data: np.ndarray, units: str | None,
         compress: bool = False) -> None:
    kw = {"compression": "gzip", "compression_opts": 4, "shuffle": True} if compress else {}
    ds = group.create_dataset(name, data=np.asarray(data), **kw)
    if units is not None:
        ds.attrs["units"] = units


def run_sync(mcap: str | Path, out: str | Path, rrd: str | Path | None = None,
             params: SyncParams | None = None) -> SyncResult:
    """Read ingest's MCAP, synchronise it, write ``out`` (and the recording) atomically."""
    from ingest.mcap_io import read_raw_mcap

    p = params or SyncParams()
    check_params(p)
    finals = {Path(x).resolve() for x in (out, rrd) if x is not None}
    if Path(mcap).resolve() in finals:
        raise BadInput(mcap, "output would overwrite the input file")
    raw = read_raw_mcap(mcap)
    result = sync_session(raw, p)
    prov = make_provenance("sync", {"mcap": str(mcap), "out": str(out),
                                    "rrd": None if rrd is None else str(rrd), **asdict(p)},
                           [mcap], SYNCED.name, SYNCED.version)
    with atomic_outputs(out, rrd) as (tmp_out, tmp_rrd):
        write_synced(tmp_out, result, prov, Path(mcap).name)
        validate_h5(tmp_out, SYNCED)
        if tmp_rrd is not None:
            from pipeline.sync_view import write_sync_recording

            write_sync_recording(result, tmp_rrd)
    return result

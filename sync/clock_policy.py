"""Which clock model a session gets, and the check that its two streams overlap.

Force that came through the mocap system's analog board (a C3D or QTM analog export:
``force.meta["clock"] == "mocap"``) shares the mocap's clock: with ``--clock auto`` there is no
offset or drift to estimate (method ``shared``). Otherwise trigger pulses when the session
recorded them (and the user did not ask for the data), else the tip's motion against the
force (:mod:`sync.clock` holds both estimators). :func:`clock_reason` says which policy
applied and why, for the calibration record. With
``--clock auto`` a dead or unplugged trigger line falls back to the data and says why; a
trigger train that fits several offsets equally well is disambiguated by the data clock.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from core.errors import BadInput
from core.series import SHARED_CLOCK, RawSession
from sync.clock import (
    ClockFit,
    clock_from_data,
    contact_lag,
    match_trigger,
    rising_edges,
    stamp_resolution_s,
)
from sync.presses import segment_presses
from sync.sync_params import SyncParams

MIN_PULSES = 3                   # trigger edges and events the trigger clock needs
SHARED = ClockFit(0.0, 0.0, 0.0, 0.0, 0.0, 0, "shared")   # one clock: exact, nothing estimated

Magnitude = Callable[[np.ndarray], np.ndarray]   # logger time (s) -> force magnitude (N)


def estimate_clock(raw: RawSession, p: SyncParams, t_m: np.ndarray, depth: np.ndarray,
                   t_f: np.ndarray, magnitude_at: Magnitude) -> tuple[ClockFit, str | None]:
    """The logger-vs-mocap clock: trigger pulses when recorded (and asked for), else data.

    With ``--clock auto`` a trigger channel that shows fewer than :data:`MIN_PULSES` edges
    (a dead or unplugged line) or a mocap file with fewer trigger events falls back to the
    data; the second value then says why (None otherwise).
    """
    if p.clock == "auto" and shares_mocap_clock(raw):
        return SHARED, None
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


def shares_mocap_clock(raw: RawSession) -> bool:
    """Whether the force was sampled by the mocap system itself (its analog board)."""
    return raw.force.meta.get("clock") == SHARED_CLOCK


def clock_reason(raw: RawSession, p: SyncParams, clock: ClockFit, note: str | None) -> str:
    """Why this clock policy applied, in words, for the calibration record."""
    f = raw.force
    if clock.method == "shared":
        return (f"force from the mocap system's analog board ({f.meta.get('format')} "
                f"{f.source}, {f.rate_hz:g} Hz): one clock, no offset or drift to estimate")
    if note is not None:
        return note
    if clock.method == "trigger":
        return (f"trigger pulses in the force log matched to the {raw.trigger_event!r} events "
                "of the mocap export")
    if p.clock == "data":
        return "--clock data: offset and drift from the tip motion against the force"
    return "no trigger recorded: offset and drift from the tip motion against the force"


def check_overlap(raw: RawSession, clock: ClockFit, t_m: np.ndarray, t_f: np.ndarray) -> None:
    """Refuse streams that share less than a second once the clock is applied."""
    lo = max(clock.to_logger(t_m[0]), t_f[0])
    hi = min(clock.to_logger(t_m[-1]), t_f[-1])
    if hi - lo < 1.0:
        raise BadInput(raw.force.source, f"force log and mocap recording do not overlap in "
                                         f"time (common span {max(hi - lo, 0):.3f} s on the "
                                         f"{clock.method} clock)")


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
                t_f: np.ndarray, magnitude_at: Magnitude) -> ClockFit:
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

"""Which clock model a session gets, and the check that its two streams overlap.

Force that came through the mocap system's analog board (a C3D or QTM analog export:
``force.meta["clock"] == "mocap"``) shares the mocap's clock: with ``--clock auto`` there is no
offset or drift to estimate (method ``shared``). Otherwise trigger pulses when the session
recorded them (and the user did not ask for the data), else the tip's motion against the
force (:mod:`sync.clock` holds both estimators). The data clock searches every offset at which
the two recordings overlap, whatever their absolute stamps (a logger stamped from its boot or
from the epoch), and is trusted only when its lock passes its checks and no other lag that
matches nearly as well passes them too (:func:`_data_clock`).
:func:`clock_reason` says which policy applied and why, for the calibration record. With
``--clock auto`` a dead or unplugged trigger line falls back to the data and says why; a
trigger train that fits several offsets equally well is disambiguated by the data clock.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from core.errors import BadInput
from core.series import SHARED_CLOCK, RawSession
from core.text import count
from sync.clock import (
    CONTENDER,
    MIN_LOCK_PRESSES,
    MIN_PULSES,
    ClockFit,
    Lock,
    clock_from_data,
    contact_lags,
    match_trigger,
    rising_edges,
    rising_presses,
    stamp_resolution_s,
)
from sync.presses import PressRule, segment_presses
from sync.sync_params import SyncParams

AMBIGUOUS_S = 0.1                # two data locks this far apart are two different offsets
PRIOR_SHARE = 0.1                # a data prior picks a trigger match if its sd is this share
#                                  of the pulse spacing (the right candidate then by 5 sd)
LOCK_CONTACT_N = 0.1             # the data lock finds presses with a contact level of at least
#                                  this (N)
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
    trigger = _trigger(raw)
    if p.clock == "trigger" and trigger is None:
        raise BadInput(raw.force.source, "--clock trigger, but the session has no trigger "
                                         "channel with matching mocap events")
    note = None
    if p.clock == "auto" and trigger is not None and min(map(len, trigger)) < MIN_PULSES:
        edges, events = trigger
        note = (f"trigger unusable ({len(edges)} pulse edges in the force log, {len(events)} "
                "trigger events in the mocap file): clock from the data")
        trigger = None
    if p.clock == "data" or trigger is None:
        return _data_clock(raw, p, t_m, depth, t_f, magnitude_at), note
    edges, events = trigger
    # both stamps are rounded: the logger's edge to its sample, the EVENT to its decimals
    step = np.median(np.diff(t_f))
    sd = float(np.sqrt((step**2 + stamp_resolution_s(np.round(events * 1e9)) ** 2) / 12))
    try:
        return match_trigger(edges, events, raw.force.source, timing_sd_s=sd,
                             min_pulses=MIN_PULSES), None
    except BadInput as e:
        if "ambiguous" not in e.what:
            raise
    prior = _trigger_prior(raw, p, t_m, depth, t_f, magnitude_at, edges)
    return match_trigger(edges, events, raw.force.source, prior=prior, timing_sd_s=sd,
                         min_pulses=MIN_PULSES), None


def _trigger_prior(raw: RawSession, p: SyncParams, t_m: np.ndarray, depth: np.ndarray,
                   t_f: np.ndarray, magnitude_at: Magnitude, edges: np.ndarray) -> ClockFit:
    """The data lock that picks among a periodic trigger's candidate offsets (a period
    apart).

    Not the full checks of :func:`_data_clock`: the trigger sets the offset, the data only
    has to say which period, so the lock is accepted when it rests on
    :data:`~sync.clock.MIN_LOCK_PRESSES` presses and its offset uncertainty is below
    :data:`PRIOR_SHARE` of the pulse spacing. Else bad input worded for a trigger session.
    """
    spacing = float(np.min(np.diff(np.sort(edges))))
    what = (f"trigger: pulse train is periodic (pulses {spacing:.3f} s apart), the match is "
            "ambiguous by whole periods")
    if np.isfinite(depth).sum() < 100:
        raise BadInput(raw.force.source, f"{what}, and the tip is tracked in too few frames "
                                         "to pick one; record a trigger with irregular "
                                         "intervals")
    lags, _ = _contact_lags(raw, p, t_m, depth, t_f, magnitude_at)
    fit, _ = _checked_lock(raw, p, t_m, depth, magnitude_at, lags[0][0])
    if fit is None or fit.n < MIN_LOCK_PRESSES or \
            not fit.offset_sd_s <= PRIOR_SHARE * spacing:
        raise BadInput(raw.force.source, f"{what}, and the tip motion cannot pick one "
                                         f"({_figures(fit)}need {MIN_LOCK_PRESSES} presses and "
                                         f"an offset uncertainty below "
                                         f"{PRIOR_SHARE * spacing * 1e3:.0f} ms); record a "
                                         "trigger with irregular intervals")
    return fit


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


def _trigger(raw: RawSession) -> tuple[np.ndarray, np.ndarray] | None:
    """The trigger's rising edges on the logger's clock and the mocap's trigger events (s);
    None where the session recorded no trigger or the mocap file no matching event."""
    f = raw.force
    if f.trigger is None or raw.trigger_event is None:
        return None
    events = np.array([t for label, t in raw.markers.events if label == raw.trigger_event],
                      float) * 1e-9
    if events.size == 0:
        return None
    return rising_edges(f.time_ns.astype(np.float64) * 1e-9, f.trigger), events


def _data_clock(raw: RawSession, p: SyncParams, t_m: np.ndarray, depth: np.ndarray,
                t_f: np.ndarray, magnitude_at: Magnitude) -> ClockFit:
    """The data lock, checked (:meth:`sync.clock.Lock.problems`) and unique.

    The best whole-session contact lag seeds the per-press lock, which must pass its checks;
    every other lag whose contact pattern matches nearly as well (:data:`CONTENDER`, as a
    strictly periodic protocol over part of a session does) must fail them, else the lock is
    ambiguous. Either failure is bad input naming the force log, with the figures.
    """
    src = raw.force.source
    if np.isfinite(depth).sum() < 100:
        raise BadInput(raw.markers.source, "clock: the tip is tracked in too few frames to "
                                           "align the force")
    lags, within = _contact_lags(raw, p, t_m, depth, t_f, magnitude_at)
    (lag0, score), rivals = lags[0], lags[1:]
    fit, problems = _checked_lock(raw, p, t_m, depth, magnitude_at, lag0)
    if fit is None or problems:
        raise BadInput(src, f"clock: the force cannot be locked to the tip motion at any "
                            f"offset {within} ({_figures(fit)}{'; '.join(problems)}); the "
                            "streams may overlap too little, or the force log is from another "
                            "session: record a trigger")
    for lag, rival_score in rivals:
        if rival_score < CONTENDER * score:
            continue
        other, wrong = _checked_lock(raw, p, t_m, depth, magnitude_at, lag)
        if other is not None and not wrong and other.n >= fit.n \
                and abs(other.offset_s - fit.offset_s) > AMBIGUOUS_S:
            raise BadInput(src, f"clock: the force locks to the tip motion equally well at "
                                f"offsets {fit.offset_s * 1e3:.3f} and "
                                f"{other.offset_s * 1e3:.3f} ms ({fit.n} presses each): the "
                                "presses are too alike in timing and shape to tell; record a "
                                "trigger")
    return fit


def _figures(fit: ClockFit | None) -> str:
    """The failed lock's offset, for its refusal."""
    if fit is None:
        return ""
    return (f"best offset {fit.offset_s * 1e3:.3f} +- {fit.offset_sd_s * 1e3:.3f} ms over "
            f"{count(fit.n, 'press')}: ")


def _contact_lags(raw: RawSession, p: SyncParams, t_m: np.ndarray, depth: np.ndarray,
                  t_f: np.ndarray, magnitude_at: Magnitude) -> tuple[list[tuple[float, float]],
                                                                     str]:
    """The whole-session contact lags (:func:`sync.clock.contact_lags`) over the searched
    offsets, and those offsets in words; refused when no offset makes the streams overlap."""
    reach = search_reach_s(p)
    within = (f"within +-{reach:g} s" if np.isfinite(reach)
              else "at which the recordings overlap")
    try:
        return contact_lags(t_m, depth, magnitude_at, (t_f[0], t_f[-1]), reach), within
    except ValueError:
        raise BadInput(raw.force.source, f"clock: force log and mocap recording do not "
                                         f"overlap in time for any clock offset {within}"
                       ) from None


def search_reach_s(p: SyncParams) -> float:
    """Largest clock offset (logger minus mocap stamps, s) the data lock searches:
    ``max_offset_s`` when set, else no bound (inf): every lag at which the two recordings
    share time, whatever their absolute stamps (a logger stamped from its boot or from the
    epoch against a mocap clock from 0)."""
    return float(p.max_offset_s) if p.max_offset_s is not None else float("inf")


def _checked_lock(raw: RawSession, p: SyncParams, t_m: np.ndarray, depth: np.ndarray,
                  magnitude_at: Magnitude, lag0: float) -> tuple[ClockFit | None, list[str]]:
    """The per-press lock from the whole-session lag ``lag0`` and what is wrong with it."""
    rate = raw.markers.rate_hz
    rule = PressRule(p.detect_n, max(p.contact_n, LOCK_CONTACT_N))
    mag = magnitude_at(t_m + lag0)
    loaded, _ = segment_presses(mag, rate, rule)
    windows = [(t_m[pr.onset:pr.release], depth[pr.onset:pr.release]) for pr in loaded]
    try:
        fit = clock_from_data(windows, magnitude_at, lag0, raw.markers.source)
    except BadInput as e:
        return None, [e.what]
    f = magnitude_at(fit.to_logger(t_m))
    ok = np.isfinite(f) & np.isfinite(depth)
    r = float(np.corrcoef(f[ok], depth[ok])[0, 1]) if ok.sum() > 10 else 0.0
    presses, _ = segment_presses(np.where(np.isfinite(f), f, np.nan), rate, rule)
    rising, checked = rising_presses([(f[pr.onset:pr.release], depth[pr.onset:pr.release])
                                      for pr in presses])
    return fit, Lock(fit, rising, checked, r).problems(p.min_correlation)

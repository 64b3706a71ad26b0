"""A session's force log made ready to resample onto the mocap frames.

The log is tared from its unloaded start and calibrated with the 6x6 matrix (gauge voltages),
checked to have started unloaded and to be uniformly sampled between its holes (stretches of
lost samples, :mod:`sync.holes`; jitter is bad input), then re-tared from the rest level next
to every press (bias creep, the tool's weight). Samples beyond the sensor's range are
flagged after resampling (:func:`over_range`), and so are the frames whose force was read
from gauge voltages on the amplifier's rail (:func:`on_rail`, :func:`near_samples`): a
clipped voltage is a wrong force that looks like a right one (a flat top a little below the
true peak).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.force_tare import (
    RestBaseline,
    Tare,
    apply_calibration,
    noise_sigma,
    rest_baseline,
    unloaded_start,
)
from core.errors import BadInput
from core.holes import Timing, find_holes
from core.series import AtiCalibration, RawSession
from sync.sync_params import SyncParams


@dataclass
class ConditionedForce:
    """The tared, calibrated and re-tared wrench on the logger's clock."""

    tare: Tare
    noise: float                 # sd of the tared force components while unloaded (N)
    contact: float               # contact level: the larger of contact_n and 5 noise widths
    time_s: np.ndarray           # (L,) logger clock, uniform between the holes
    wrench: np.ndarray           # (L, 6) Fx..Tz, the re-tare subtracted
    rest: RestBaseline           # the re-tare (empty when switched off)
    timing: Timing               # the log's period and holes

    @property
    def stretches(self) -> list[tuple[int, int]]:
        """The uniform runs of samples between the holes, as [start, stop) pairs."""
        return self.timing.stretches(len(self.time_s))


def condition_force(raw: RawSession, p: SyncParams) -> ConditionedForce:
    """Tare, calibrate, check and re-tare the session's force log."""
    tare, wrench, noise = tare_and_calibrate(raw, p)
    return retared(raw, p, tare, wrench, noise)


def retared(raw: RawSession, p: SyncParams, tare: Tare, wrench: np.ndarray, noise: float
            ) -> ConditionedForce:
    """The tared, calibrated ``wrench`` (L, 6) of ``raw``'s force log re-tared from its rest
    next to every press (unless ``p.retare`` is off), with the log's clock and holes; the
    contact level is the larger of ``p.contact_n`` and 5 noise widths. Sync tares the log
    from its start; ``pipeline live`` with the session's tare, stretch by stretch."""
    contact = contact_level(p, noise)
    t_f, timing = force_times(raw)
    rest = (rest_baseline(t_f, wrench, contact, max(contact, 0.5 * p.detect_n)) if p.retare
            else RestBaseline(np.empty(0), np.empty((0, wrench.shape[1]))))
    return ConditionedForce(tare, noise, contact, t_f, wrench - rest.at(t_f), rest, timing)


def contact_level(p: SyncParams, noise: float) -> float:
    """The force a contact must exceed (N): ``p.contact_n``, or 5 noise widths if higher."""
    return max(p.contact_n, 5 * noise)


def tare_and_calibrate(raw: RawSession, p: SyncParams) -> tuple[Tare, np.ndarray, float]:
    """Tare and calibrate the log: (tare, wrench, noise of the tared force in N).

    A start under load passes the tare's flatness test when it is held steady, but then the
    force does not come back to zero after the first press: the rest it returns to is
    compared with the contact level (5 noise widths at least), well above the creep of the
    bias over one press cycle.
    """
    f = raw.force
    matrix = None
    if f.kind == "gauge":
        if raw.calibration is None:
            raise BadInput(f.source, "gauge voltages but no ATI calibration in the session")
        matrix = raw.calibration.matrix
    if not np.isfinite(f.values).all():
        bad = int(np.flatnonzero(~np.isfinite(f.values).all(axis=1))[0])
        raise BadInput(f.source, "force log has missing samples", where=f"sample {bad}")
    tare = unloaded_start(f.values, f.rate_hz, f.source)
    wrench = apply_calibration(f.values, tare.bias, matrix)
    noise = noise_level(wrench, tare)
    contact = contact_level(p, noise)
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


def force_times(raw: RawSession) -> tuple[np.ndarray, Timing]:
    """Logger times (s) and the log's holes; the resampler needs a uniform grid between the
    holes, so jitter is bad input (:func:`core.holes.find_holes`), and so is a log too short
    to filter."""
    f = raw.force
    if len(f.time_ns) < 64:
        raise BadInput(f.source, f"force log is too short ({len(f.time_ns)} samples)")
    return f.time_ns.astype(np.float64) * 1e-9, find_holes(f.time_ns, f.source,
                                                           "force samples")


def noise_level(wrench: np.ndarray, tare: Tare) -> float:
    """Standard deviation of the force magnitude's components while unloaded (N)."""
    return float(np.max(wrench[tare.start:tare.stop, :3].std(axis=0)))


def beyond_rating(wrench: np.ndarray, calibration: AtiCalibration | None) -> np.ndarray:
    """Samples of a wrench (T, 6) beyond ``calibration``'s rated load on any axis (none
    without a calibration, which alone states the rating); NaN is never beyond it."""
    if calibration is None:
        return np.zeros(len(wrench), bool)
    limit = np.asarray(calibration.max_load, float)
    with np.errstate(invalid="ignore"):
        return np.asarray((np.abs(wrench) > limit).any(axis=1))


RAIL_TOLERANCE = 0.005      # a gauge within this share of the output range of a rail is on it
FLAT_RUN = 8                # identical samples at a channel's extreme: a flat top
FLAT_SIGMAS = 20.0          # ... that far from the channel's median (not a quiet channel)
FLAT_MIN_STEPS = 1.0        # ... on a channel whose noise is this many quantisation steps wide


def output_rails(raw: RawSession) -> tuple[float, float] | None:
    """The amplifier's output range (V) of a gauge log, from the ATI calibration's
    ``OutputRange`` and ``OutputBipolar`` (a bipolar 20 V range is -10..+10 V); None when the
    force is no gauge log or the calibration does not say."""
    return rails(raw.force.kind, raw.calibration)


def rails(kind: str, calibration: AtiCalibration | None) -> tuple[float, float] | None:
    """:func:`output_rails` of a force of ``kind`` read through ``calibration``."""
    if kind != "gauge" or calibration is None:
        return None
    cal = calibration.meta.get("calibration", {})
    try:
        span = float(cal["OutputRange"])
    except (KeyError, TypeError, ValueError):
        return None
    if not (np.isfinite(span) and span > 0):
        return None
    bipolar = str(cal.get("OutputBipolar", "True")).strip().lower() != "false"
    return (-span / 2, span / 2) if bipolar else (0.0, span)


def on_rail(raw: RawSession) -> np.ndarray:
    """Log samples (L,) where any gauge channel sits on the amplifier's rail.

    On a rail: within :data:`RAIL_TOLERANCE` of the output range of either end of it
    (:func:`output_rails`), or in a flat top: a run of :data:`FLAT_RUN` identical values at a
    channel's own highest or lowest value, far (:data:`FLAT_SIGMAS` noise widths) from its
    median (an amplifier or converter that clips below the range the .cal states, or a .cal
    that does not state it; a noisy gauge never repeats its extreme). The flat-top rule
    needs a channel whose noise width (:func:`calib.force_tare.noise_sigma`) is at least
    :data:`FLAT_MIN_STEPS` quantisation step (:func:`quantisation_step`), i.e. whose noise
    moves most consecutive samples (the width is then 1.05 steps or more; it is the 0.29-step
    rounding floor when most are equal). Where the noise is below that (a quiet 16-bit DAQ,
    a CSV written with few decimals) the slow peak of the strongest press is a run of one
    value too, and a clip at an unknown level cannot be told from it. A wrench log (already
    in N) has no rail: its limit is the rated range (:func:`over_range`).
    """
    v = np.asarray(raw.force.values, float)
    if raw.force.kind != "gauge":
        return np.zeros(len(v), bool)
    flagged = at_rails(v, output_rails(raw))
    sigma = noise_sigma(v)
    for c, s in zip(v.T, sigma, strict=True):
        if not s >= FLAT_MIN_STEPS * quantisation_step(c):
            continue
        med = np.median(c)
        for extreme in (np.max(c), np.min(c)):
            if abs(extreme - med) > FLAT_SIGMAS * s:
                flagged |= _runs_at_least(c == extreme, FLAT_RUN)
    return flagged


def at_rails(volts: np.ndarray, rails: tuple[float, float] | None) -> np.ndarray:
    """Samples (L,) where any gauge channel of ``volts`` (L, C) lies within
    :data:`RAIL_TOLERANCE` of the output range of either of the amplifier's ``rails`` (none
    where the rails are unknown)."""
    v = np.asarray(volts, float)
    if rails is None:
        return np.zeros(len(v), bool)
    lo, hi = rails
    tol = RAIL_TOLERANCE * (hi - lo)
    return np.asarray(((v <= lo + tol) | (v >= hi - tol)).any(axis=1))


def quantisation_step(values: np.ndarray) -> float:
    """The smallest nonzero difference between a channel's distinct values: its converter's
    step, or the last decimal its CSV was written with (0 for a constant channel)."""
    d = np.diff(np.unique(np.asarray(values, float)))
    return float(d.min()) if d.size else 0.0


def _runs_at_least(mask: np.ndarray, length: int) -> np.ndarray:
    """``mask`` kept only in its True runs of at least ``length`` samples."""
    out = np.zeros(len(mask), bool)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        if b - a >= length:
            out[a:b] = True
    return out


def near_samples(t_samples_s: np.ndarray, flagged: np.ndarray, t_query_s: np.ndarray,
                 reach_s: float) -> np.ndarray:
    """Queries (logger times) within ``reach_s`` of a flagged sample: a resampled value is
    made of the log samples within the filter's half length of it."""
    hit = np.asarray(t_samples_s, float)[np.asarray(flagged, bool)]
    q = np.asarray(t_query_s, float)
    if hit.size == 0:
        return np.zeros(len(q), bool)
    j = np.clip(np.searchsorted(hit, q), 1, max(len(hit) - 1, 1))
    near = np.minimum(np.abs(q - hit[j - 1]), np.abs(q - hit[np.minimum(j, len(hit) - 1)]))
    return np.where(np.isfinite(q), near <= reach_s, False)

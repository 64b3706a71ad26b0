"""A session's force log made ready to resample onto the mocap frames.

The log is tared from its unloaded start and calibrated with the 6x6 matrix (gauge voltages),
checked to have started unloaded and to be uniformly sampled, then re-tared from the rest level
next to every press (bias creep, the tool's weight). Samples beyond the sensor's range are
flagged after resampling (:func:`over_range`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core.errors import BadInput
from core.series import RawSession
from sync.force import RestBaseline, Tare, apply_calibration, rest_baseline, unloaded_start
from sync.sync_params import SyncParams


@dataclass
class ConditionedForce:
    """The tared, calibrated and re-tared wrench on the logger's clock."""

    tare: Tare
    noise: float                 # sd of the tared force components while unloaded (N)
    contact: float               # contact level: the larger of contact_n and 5 noise widths
    time_s: np.ndarray           # (L,) logger clock, uniform
    wrench: np.ndarray           # (L, 6) Fx..Tz, the re-tare subtracted
    rest: RestBaseline           # the re-tare (empty when switched off)


def condition_force(raw: RawSession, p: SyncParams) -> ConditionedForce:
    """Tare, calibrate, check and re-tare the session's force log."""
    tare, wrench, noise = tare_and_calibrate(raw, p)
    contact = max(p.contact_n, 5 * noise)
    t_f = force_times(raw)
    rest = (rest_baseline(t_f, wrench, contact, max(contact, 0.5 * p.detect_n)) if p.retare
            else RestBaseline(np.empty(0), np.empty((0, wrench.shape[1]))))
    return ConditionedForce(tare, noise, contact, t_f, wrench - rest.at(t_f), rest)


def tare_and_calibrate(raw: RawSession, p: SyncParams) -> tuple[Tare, np.ndarray, float]:
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
    noise = noise_level(wrench, tare)
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


def force_times(raw: RawSession) -> np.ndarray:
    """Logger times (s); the resampler needs a uniform grid, so jitter is bad input."""
    t = raw.force.time_ns.astype(np.float64) * 1e-9
    step = np.diff(t)
    nominal = np.median(step)
    jitter = np.abs(step - nominal).max() if len(step) else 0.0
    if len(t) < 64 or jitter > 0.1 * nominal:
        raise BadInput(raw.force.source, "force log is too short or not uniformly sampled "
                                         f"(largest step deviation {jitter * 1e3:.3f} ms)")
    return t


def noise_level(wrench: np.ndarray, tare: Tare) -> float:
    """Standard deviation of the force magnitude's components while unloaded (N)."""
    return float(np.max(wrench[tare.start:tare.stop, :3].std(axis=0)))


def over_range(raw: RawSession, sampled: np.ndarray) -> np.ndarray:
    """Samples (T, 6) beyond the calibration's rated load on any axis."""
    if raw.calibration is None:
        return np.zeros(len(sampled), bool)
    limit = np.asarray(raw.calibration.max_load, float)
    with np.errstate(invalid="ignore"):
        return (np.abs(sampled) > limit).any(axis=1)

"""The time-series containers every reader returns and every later step passes along.

All arrays are SI: positions in metres, time as int64 nanoseconds on the recording device's own
clock (0 at its first sample unless the file says otherwise). Missing samples are NaN.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from core.errors import BadInput
from core.units import TIME_UNITS

_NS_LIMIT = float(2**63 - 2**10)       # |ns| below this rounds and casts to int64 safely


def time_to_ns(t: Any, source: str | Path, unit: str = "s",
               where: Callable[[int], str] | None = None) -> np.ndarray:
    """Times in ``unit`` (s, ms, us, ns) as int64 ns, rounded to the nearest nanosecond.

    Integer times in a whole number of ns per unit are converted exactly. A missing, infinite
    or out-of-range time (int64 ns spans +-292 years) is bad input; ``where(i)`` names the
    place of sample ``i`` ("line 12").
    """
    t = np.asarray(t)
    scale = TIME_UNITS[unit]
    if t.dtype.kind in "iu" and scale == int(scale):
        limit = np.iinfo(np.int64).max // int(scale)
        bad = np.flatnonzero((t > limit) | (t < -limit))
        ns = None if bad.size else t.astype(np.int64) * int(scale)
    else:
        with np.errstate(over="ignore", invalid="ignore"):
            scaled = t.astype(np.float64) * scale
        bad = np.flatnonzero(~(np.abs(scaled) < _NS_LIMIT))        # NaN fails too
        ns = None if bad.size else np.rint(scaled).astype(np.int64)
    if ns is None:
        i = int(bad[0])
        raise BadInput(source, f"time {t[i]} {unit} is missing, infinite or beyond the int64 "
                               "nanosecond range (+-292 years)",
                       where=None if where is None else where(i))
    return ns


def frame_times_ns(frames: int, rate_hz: float, source: str | Path, what: str = "frame rate",
                   where: str | None = None) -> np.ndarray:
    """The time of frame ``i``, ``i / rate_hz``, in int64 ns, for a file timed by its rate.

    ``what`` names the rate in the file (``FREQUENCY``, ``POINT:RATE``). No frames, a rate that
    is not positive, one too high for distinct nanoseconds or too low for int64 is bad input.
    """
    if frames < 1:
        raise BadInput(source, "holds no frames")
    if not (np.isfinite(rate_hz) and 0 < rate_hz <= 1e9):
        raise BadInput(source, f"{what} {rate_hz:g} is not a frame rate (0 to 1e9 Hz)",
                       where=where)
    if not (frames - 1) * 1e9 / float(rate_hz) < _NS_LIMIT:
        raise BadInput(source, f"{what} {rate_hz:g} is too low: {frames} frames last beyond "
                               "the int64 nanosecond range", where=where)
    return np.rint(np.arange(frames, dtype=np.float64) * 1e9 / rate_hz).astype(np.int64)


def check_time(time_ns: np.ndarray, source: str | Path) -> None:
    """Time must be finite and strictly increasing; otherwise the file is bad input."""
    t = np.asarray(time_ns)
    if t.ndim != 1:
        raise BadInput(source, f"time must be one-dimensional, got shape {t.shape}")
    if t.size > 1:
        steps = np.diff(t)
        bad = np.flatnonzero(steps <= 0)
        if bad.size:
            i = int(bad[0]) + 1
            raise BadInput(source, f"time is not increasing at sample {i}", where=f"frame {i}")


class _Tracked:
    """Frame count and missing samples, shared by marker and body series."""

    time_ns: np.ndarray
    positions: np.ndarray

    @property
    def frames(self) -> int:
        return int(self.time_ns.shape[0])

    def missing_samples(self) -> int:
        """Number of (frame, marker or body) samples with no position."""
        return int(np.isnan(self.positions).any(axis=2).sum())


@dataclass
class MarkerSeries(_Tracked):
    """3D marker trajectories: ``positions[t, m] = (x, y, z)`` in metres, NaN where missing."""

    source: str
    time_ns: np.ndarray            # (T,) int64
    labels: list[str]              # (M,)
    positions: np.ndarray          # (T, M, 3) float64, metres
    rate_hz: float
    residuals: np.ndarray | None = None   # (T, M) float64 metres, NaN where missing
    events: list[tuple[str, int]] = field(default_factory=list)  # (label, time_ns)
    meta: dict[str, Any] = field(default_factory=dict)

    def select(self, names: list[str]) -> np.ndarray:
        """Positions of the named markers, ``(T, len(names), 3)``; a missing name is bad input."""
        index = {n: i for i, n in enumerate(self.labels)}
        absent = [n for n in names if n not in index]
        if absent:
            raise BadInput(self.source, f"marker(s) not in file: {', '.join(absent)}")
        return self.positions[:, [index[n] for n in names]]


@dataclass
class BodySeries(_Tracked):
    """6DOF rigid bodies: position (m), rotation matrix (body to lab), residual; NaN when lost."""

    source: str
    time_ns: np.ndarray            # (T,) int64
    bodies: list[str]              # (B,)
    positions: np.ndarray          # (T, B, 3) float64, metres
    rotations: np.ndarray          # (T, B, 3, 3) float64
    residuals: np.ndarray          # (T, B) float64 metres; NaN when lost
    rate_hz: float
    events: list[tuple[str, int]] = field(default_factory=list)
    meta: dict[str, Any] = field(default_factory=dict)



SHARED_CLOCK = "mocap"     # ForceSeries.meta["clock"] of force sampled by the mocap system


@dataclass
class ForceSeries:
    """A force-sensor log: raw channels (gauge volts or calibrated wrench) on the logger's clock,
    or, with ``meta["clock"] == SHARED_CLOCK``, on the mocap's (its analog board sampled them;
    time 0 at the first mocap frame)."""

    source: str
    time_ns: np.ndarray            # (T,) int64
    channels: list[str]            # (C,) names as in the file
    values: np.ndarray             # (T, C) float64
    units: list[str]               # (C,) e.g. "V", "N", "N*m"
    kind: str                      # "gauge" (volts) or "wrench" (Fx, Fy, Fz, Tx, Ty, Tz)
    rate_hz: float
    trigger: np.ndarray | None = None     # (T,) float64 sync/trigger channel when logged
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def frames(self) -> int:
        return int(self.time_ns.shape[0])


@dataclass
class AtiCalibration:
    """An ATI calibration: ``wrench = matrix @ (volts - bias)``, forces in N, torques in N*m."""

    source: str
    serial: str
    body_style: str
    calibration: str               # e.g. "SI-12-0.12"
    matrix: np.ndarray             # (6, 6) float64, rows Fx, Fy, Fz, Tx, Ty, Tz, SI units
    max_load: np.ndarray           # (6,) rated range in SI (N, N*m)
    force_units: str               # as the file states them
    torque_units: str
    meta: dict[str, Any] = field(default_factory=dict)


@dataclass
class RawSession:
    """Everything ``pipeline ingest`` stores in its MCAP file and ``read_raw_mcap`` gives back.

    Each stream stays on its own device clock; nothing is synchronised or calibrated yet.
    """

    name: str
    markers: MarkerSeries                    # the trial's 3D export (phantom + indenter markers)
    force: ForceSeries                       # raw force log (gauge volts or wrench)
    phantom_markers: list[str]               # the surface markers (N >= 4), session.toml order
    indenter_markers: list[str]              # the indenter cluster (4), in session.toml order
    calibration: AtiCalibration | None = None   # required when force.kind == "gauge"
    bodies: BodySeries | None = None         # QTM 6D export of the indenter, when present
    pivot: MarkerSeries | None = None        # pivot-calibration recording, when present
    trigger_event: str | None = None         # EVENT label of mocap sync pulses, when used
    phantom: dict | None = None              # session.toml's [phantom] layout as JSON (m);
                                             # None: the paper's 100 mm square grid
    provenance: dict[str, Any] = field(default_factory=dict)

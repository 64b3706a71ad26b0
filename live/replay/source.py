"""What ``pipeline replay`` plays, read once: a session folder (through ingest's own reading
of it, :func:`ingest.ingest_stage.load_session`) or an MCAP that ingest wrote
(:func:`ingest.mcap_io.read_raw_mcap`).

The replay serves what a QTM would: the session's markers (phantom, then indenter, in
session.toml's order) in mm, NaN when lost, at the mocap's frames; and the force as one analog
device (its channels, then the trigger channel when logged), or, where it came from a QTM
force-plate export (its series names the plate), as that force plate: per sample the force (N),
its moment (N m) and its point of application (mm), which the session does not keep and the
replay takes where the force's line of action meets the plate's top surface
(:func:`core.force_plate.centre_of_pressure`, the plate's origin on that surface). Each frame
carries the samples from half a sample before its time to half a sample before the next
frame's. Force through the mocap's analog board or a force plate (``pipeline synth --force-via
analog`` or ``plate``) shares the frames' clock, so every sample lands in its own frame. A
force log on its own clock (a logger) has no common clock with the mocap until sync finds one:
its samples are apportioned by their own time read as if on the mocap's clock, so that the live
client sees one clock as it would from QTM; samples before the first frame or after the last
are left out (counted). A sample's number is its index in the session's force stream.

A wrench from any other sensor is served as analog channels, not as a force plate: a
plate's point of application needs a plate that such a session does not have.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.errors import BadInput
from core.force_plate import centre_of_pressure
from core.series import SHARED_CLOCK, ForceSeries, RawSession
from data_schema.session import read_session
from ingest.ingest_stage import load_session
from ingest.mcap_io import read_raw_mcap
from ingest.qtm_force_plate import COLUMNS, UNITS, WRENCH
from live.protocol.packets import Component

# QTM's words for the units of analog channels: an analog board's volts, and a force
# device's newtons and newton metres (so QTM words them in a 1.25 parameters document that the
# vendor's C++ client is tested on; not "N" and "Nm")
QTM_UNITS = {"V": "V", "N": "newtons", "N*m": "newtonmetre"}
TRIGGER_UNIT = "V"
PLATE_NAME = "Force-plate 1"      # a plate's name where its export stated none


@dataclass(frozen=True)
class Plate:
    """What the session knows of the plate that measured its force: its type and corners
    (QTM's corners 1 to 4, lab, mm) where the export stated them."""

    type: str | None
    corners_mm: list[list[float]] | None


@dataclass(frozen=True)
class ForceDevice:
    """The force as one analog device, or as one force plate (``plate`` not None):
    ``values`` (S, C) are the samples served, of which frame ``i`` carries
    ``values[bounds[i]:bounds[i + 1]]``; ``values[0]`` is sample number ``first_sample`` of the
    session's force stream."""

    name: str
    labels: list[str]
    units: list[str]             # QTM's unit words (QTM_UNITS)
    rate_hz: float
    values: np.ndarray           # (S, C) float32
    bounds: np.ndarray           # (T + 1,) int64
    first_sample: int
    left_out: int                # samples outside the frames (a log on its own clock)
    plate: Plate | None = None

    @property
    def component(self) -> Component:
        """The data component that carries the samples."""
        return Component.ANALOG if self.plate is None else Component.FORCE

    def describe(self) -> str:
        """What is served, in words."""
        return f"{len(self.labels)} analog channels" if self.plate is None else \
            f"force plate {self.name!r}"

    def samples(self, start: int, stop: int) -> tuple[int, np.ndarray]:
        """The number of the first sample of frames ``start`` to ``stop - 1`` and their
        samples (n, C)."""
        lo, hi = int(self.bounds[start]), int(self.bounds[stop])
        return self.first_sample + lo, self.values[lo:hi]


@dataclass(frozen=True)
class ReplaySource:
    """A session as the replay serves it: frame times on the mocap's clock, the markers in mm
    (float32, NaN when lost) in the order of ``labels``, and the force as an analog device or
    a force plate."""

    name: str
    path: str
    labels: list[str]
    rate_hz: float
    time_ns: np.ndarray          # (T,) int64
    markers_mm: np.ndarray       # (T, M, 3) float32
    force: ForceDevice
    clock: str                   # the force's clock: "mocap" (shared) or "log" (its own)

    @property
    def frames(self) -> int:
        return int(self.time_ns.shape[0])

    def timestamp_us(self, frame: int) -> int:
        """Frame ``frame``'s time in whole microseconds (rounded)."""
        return (int(self.time_ns[frame]) + 500) // 1000


def read_replay_source(path: str | Path) -> ReplaySource:
    """The session in the folder ``path`` (or its ``session.toml``), or the ingested MCAP
    ``path``; anything else is bad input naming it."""
    path = Path(path)
    if path.is_file() and path.name == "session.toml":
        path = path.parent
    if path.is_dir():
        session = load_session(read_session(path))
    elif path.is_file():
        session = read_raw_mcap(path)
    else:
        raise BadInput(path, "no such session folder or MCAP file")
    return replay_source(session, str(path))


def replay_source(session: RawSession, path: str) -> ReplaySource:
    """What to serve of ``session`` (read from ``path``)."""
    m = session.markers
    labels = list(session.phantom_markers) + list(session.indenter_markers)
    markers_mm = (m.select(labels) * 1e3).astype(np.float32)
    frame_ns = np.asarray(m.time_ns, dtype=np.int64)
    if frame_ns.size == 0:
        raise BadInput(m.source, "holds no frames to replay")
    clock = "mocap" if session.force.meta.get("clock") == SHARED_CLOCK else "log"
    return ReplaySource(session.name, path, labels, float(m.rate_hz), frame_ns, markers_mm,
                        force_device(session.force, frame_ns, float(m.rate_hz)), clock)


def force_device(force: ForceSeries, frame_ns: np.ndarray, rate_hz: float) -> ForceDevice:
    """The force's samples apportioned to the frames at ``frame_ns``: a plate's force, moment
    and point of application where a force plate measured it (its series names the plate and
    holds its wrench, Force_X .. Moment_Z), else the channels (and trigger) as an analog
    device."""
    plate = "plate" in force.meta and list(force.channels) == WRENCH
    labels, units, values = _plate_values(force) if plate else _channel_values(force)
    bounds = apportion(np.asarray(force.time_ns, dtype=np.int64), frame_ns, rate_hz,
                       force.rate_hz)
    lo, hi = int(bounds[0]), int(bounds[-1])
    return ForceDevice(
        name=(force.meta["plate"] or PLATE_NAME) if plate else Path(force.source).name,
        labels=labels, units=units, rate_hz=float(force.rate_hz),
        values=values[lo:hi].astype(np.float32), bounds=bounds - lo, first_sample=lo,
        left_out=force.frames - (hi - lo),
        plate=Plate(force.meta.get("plate_type"), force.meta.get("plate_corners_mm"))
        if plate else None)


def _channel_values(force: ForceSeries) -> tuple[list[str], list[str], np.ndarray]:
    """An analog device's labels, QTM's unit words and samples: the channels, then the
    trigger where logged."""
    labels, units = list(force.channels), [QTM_UNITS.get(u, u) for u in force.units]
    values = np.asarray(force.values, dtype=np.float64).reshape(force.frames, -1)
    if force.trigger is not None:
        labels.append(str(force.meta.get("trigger_column") or "trigger"))
        units.append(TRIGGER_UNIT)
        values = np.column_stack([values, force.trigger])
    return labels, units, values


def _plate_values(force: ForceSeries) -> tuple[list[str], list[str], np.ndarray]:
    """A plate's nine values a sample, named and united as QTM's force export: the wrench
    (N, N m) and its centre of pressure (mm)."""
    wrench = np.asarray(force.values, dtype=np.float64).reshape(force.frames, -1)
    cop_mm = centre_of_pressure(wrench[:, :3], wrench[:, 3:6]) * 1e3
    return list(COLUMNS), [UNITS[c] for c in COLUMNS], np.column_stack([wrench[:, :6],
                                                                         cop_mm])


def apportion(sample_ns: np.ndarray, frame_ns: np.ndarray, frame_hz: float,
              sample_hz: float) -> np.ndarray:
    """``bounds`` (T + 1,): frame ``i`` holds samples ``bounds[i]`` to ``bounds[i + 1] - 1``,
    those from half a sample before its time to half a sample before the next frame's (the
    last frame: before its time plus a frame period)."""
    half = round(0.5e9 / sample_hz)
    edges = np.append(frame_ns, frame_ns[-1] + round(1e9 / frame_hz)) - half
    return np.searchsorted(sample_ns, edges, side="left").astype(np.int64)

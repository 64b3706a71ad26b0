"""What ``pipeline replay`` plays, read once: a session folder (through ingest's own reading
of it, :func:`ingest.ingest_stage.load_session`) or an MCAP that ingest wrote
(:func:`ingest.mcap_io.read_raw_mcap`).

The replay serves what a QTM would: the session's markers (phantom, then indenter, in
session.toml's order) in mm, NaN when lost, at the mocap's frames; and the force as one analog
device (its channels, then the trigger channel when logged). Each frame carries the samples from
half a sample before its time to half a sample before the next frame's. Force through the
mocap's analog board (``pipeline synth --force-via analog``) shares the frames' clock, so every
sample lands in its own frame. A force log on its own clock (a logger) has no common clock with
the mocap until sync finds one: its samples are apportioned by their own time read as if on the
mocap's clock, so that the live client sees one clock as it would from QTM; samples before the
first frame or after the last are left out (counted). A sample's number is its index in the
session's force stream.

A wrench is served as analog channels too, not as a QTM force plate: a plate's point of
application and moments need a plate's geometry that a lab session does not have.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.errors import BadInput
from core.series import SHARED_CLOCK, ForceSeries, RawSession
from data_schema.session import read_session
from ingest.ingest_stage import load_session
from ingest.mcap_io import read_raw_mcap

# QTM's words for the units of analog channels: an analog board's volts, and a force
# device's newtons and newton metres (so QTM words them in a 1.25 parameters document that the
# vendor's C++ client is tested on; not "N" and "Nm")
QTM_UNITS = {"V": "V", "N": "newtons", "N*m": "newtonmetre"}
TRIGGER_UNIT = "V"


@dataclass(frozen=True)
class AnalogDevice:
    """The force as one analog device: ``values`` (S, C) are the samples served, of which
    frame ``i`` carries ``values[bounds[i]:bounds[i + 1]]``; ``values[0]`` is sample number
    ``first_sample`` of the session's force stream."""

    name: str
    labels: list[str]
    units: list[str]             # QTM's unit words (QTM_UNITS)
    rate_hz: float
    values: np.ndarray           # (S, C) float32
    bounds: np.ndarray           # (T + 1,) int64
    first_sample: int
    left_out: int                # samples outside the frames (a log on its own clock)

    def samples(self, start: int, stop: int) -> tuple[int, np.ndarray]:
        """The number of the first sample of frames ``start`` to ``stop - 1`` and their
        samples (n, C)."""
        lo, hi = int(self.bounds[start]), int(self.bounds[stop])
        return self.first_sample + lo, self.values[lo:hi]


@dataclass(frozen=True)
class ReplaySource:
    """A session as the replay serves it: frame times on the mocap's clock, the markers in mm
    (float32, NaN when lost) in the order of ``labels``, and the force as an analog device."""

    name: str
    path: str
    labels: list[str]
    rate_hz: float
    time_ns: np.ndarray          # (T,) int64
    markers_mm: np.ndarray       # (T, M, 3) float32
    analog: AnalogDevice
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
                        analog_device(session.force, frame_ns, float(m.rate_hz)), clock)


def analog_device(force: ForceSeries, frame_ns: np.ndarray, rate_hz: float) -> AnalogDevice:
    """The force's channels (and trigger) apportioned to the frames at ``frame_ns``."""
    labels, units = list(force.channels), [QTM_UNITS.get(u, u) for u in force.units]
    values = np.asarray(force.values, dtype=np.float64).reshape(force.frames, -1)
    if force.trigger is not None:
        labels.append(str(force.meta.get("trigger_column") or "trigger"))
        units.append(TRIGGER_UNIT)
        values = np.column_stack([values, force.trigger])
    bounds = apportion(np.asarray(force.time_ns, dtype=np.int64), frame_ns, rate_hz,
                       force.rate_hz)
    lo, hi = int(bounds[0]), int(bounds[-1])
    return AnalogDevice(
        name=Path(force.source).name, labels=labels, units=units, rate_hz=float(force.rate_hz),
        values=values[lo:hi].astype(np.float32), bounds=bounds - lo, first_sample=lo,
        left_out=force.frames - (hi - lo))


def apportion(sample_ns: np.ndarray, frame_ns: np.ndarray, frame_hz: float,
              sample_hz: float) -> np.ndarray:
    """``bounds`` (T + 1,): frame ``i`` holds samples ``bounds[i]`` to ``bounds[i + 1] - 1``,
    those from half a sample before its time to half a sample before the next frame's (the
    last frame: before its time plus a frame period)."""
    half = round(0.5e9 / sample_hz)
    edges = np.append(frame_ns, frame_ns[-1] + round(1e9 / frame_hz)) - half
    return np.searchsorted(sample_ns, edges, side="left").astype(np.int64)

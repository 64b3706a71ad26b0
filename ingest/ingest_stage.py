"""The ingest stage runner: a raw session folder (lab files + session.toml) into one MCAP file.

Reads every file the session names with the lab readers, which check each file on its own
(unique names, numbers, increasing time, a finite 6x6 calibration); checks that the files agree
with the session (every named marker, body, EVENT and force-log column present); and writes the
streams, each on its own device clock, to one MCAP file (:mod:`data_schema.raw_mcap`) and,
optionally, a rerun recording. Nothing is written under the output names unless everything
succeeds; inputs are only read.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict
from pathlib import Path
from typing import TypeVar

import numpy as np

from core.atomic import atomic_outputs, same_path
from core.errors import BadInput
from core.progress import progress
from core.provenance import make_provenance
from core.series import (
    SHARED_CLOCK,
    AtiCalibration,
    BodySeries,
    ForceSeries,
    MarkerSeries,
    RawSession,
)
from data_schema.raw_mcap import SCHEMA, VERSION, validate_raw_mcap
from data_schema.session import SessionConfig, read_session
from ingest.analog import samples_per_frame
from ingest.ati_cal import read_ati_cal
from ingest.detect import detect_format, read_mocap
from ingest.force_source import read_force
from ingest.ingest_params import IngestParams
from ingest.ingest_view import write_ingest_recording
from ingest.mcap_io import write_raw_mcap
from ingest.qtm_6d import read_qtm_6d

T = TypeVar("T")


def run_ingest(inputs: str | Path, out: str | Path, params: IngestParams | None = None,
               rrd: str | Path | None = None) -> RawSession:
    """Read, check and store the session in the folder ``inputs`` as the MCAP ``out``;
    ``rrd`` also writes the recording."""
    folder, params = inputs, params or IngestParams()
    cfg = read_session(folder)
    files = session_inputs(cfg)
    if rrd is not None and same_path(out, rrd):
        raise BadInput(out, "--rrd and --out name the same file")
    clash = [p for p in files if any(same_path(p, o) for o in (out, rrd) if o is not None)]
    if clash:
        raise BadInput(clash[0], "output would overwrite an input file")
    # Hashing the inputs (hashlib frees the GIL) overlaps with parsing them.
    with ThreadPoolExecutor(max_workers=1) as pool:
        provenance = pool.submit(make_provenance, "ingest", asdict(params), files, SCHEMA,
                                 VERSION)
        session = load_session(cfg)
        session.provenance = provenance.result()
    with atomic_outputs(out, rrd) as (tmp_out, tmp_rrd):
        write_raw_mcap(tmp_out, session, {"provenance": session.provenance}, params.compression)
        validate_raw_mcap(tmp_out, deep=False)   # blocks are checked on every read
        if tmp_rrd is not None:
            write_ingest_recording(session, tmp_rrd)
    return session


def session_inputs(cfg: SessionConfig) -> list[Path]:
    """Every file the session reads, session.toml first (for the provenance hashes)."""
    files = [cfg.folder / "session.toml", cfg.mocap.file, cfg.mocap.bodies_file,
             cfg.force.file, cfg.force.calibration, cfg.pivot_file]
    return list(dict.fromkeys(f for f in files if f is not None))   # a C3D may serve twice


def load_session(cfg: SessionConfig) -> RawSession:
    """Read every file of the session with the lab readers and check them against it."""
    m = cfg.mocap
    steps = ["mocap", "bodies", "force", "calibration", "pivot"]
    got: dict[str, object] = {}
    with progress(steps, label="ingest: reading") as bar:
        for step in bar:
            got[step] = _READ[step](cfg)
            if step == "mocap":     # before the other files are read
                _require_markers(_got(got, step, MarkerSeries),
                                 m.phantom_markers + m.indenter_markers)
    markers, force = _got(got, "mocap", MarkerSeries), _got(got, "force", ForceSeries)
    _check_shared_clock(markers, force)
    if m.trigger_event and m.trigger_event not in {e for e, _ in markers.events}:
        raise BadInput(m.file, f"no EVENT labelled {m.trigger_event!r} (session.toml "
                               f"trigger_event)")
    pivot = None if got["pivot"] is None else _got(got, "pivot", MarkerSeries)
    if pivot is not None:
        _require_markers(pivot, m.indenter_markers)
    return RawSession(
        name=cfg.name, markers=markers, force=force,
        phantom_markers=list(m.phantom_markers), indenter_markers=list(m.indenter_markers),
        calibration=None if got["calibration"] is None else
        _got(got, "calibration", AtiCalibration),
        bodies=None if got["bodies"] is None else _got(got, "bodies", BodySeries), pivot=pivot,
        trigger_event=m.trigger_event, phantom=cfg.phantom.as_json(),
    )


def _got(got: dict[str, object], step: str, kind: type[T]) -> T:
    """What the reader of ``step`` read, as the ``kind`` it returns."""
    value = got[step]
    if not isinstance(value, kind):
        raise TypeError(f"ingest: reading the {step} gave a {type(value).__name__}")
    return value


def _read_mocap(cfg: SessionConfig) -> MarkerSeries:
    """The trial's 3D export (QTM TSV 3D, C3D or QTM MAT), read once."""
    return read_mocap(cfg.mocap.file)


def _read_pivot(cfg: SessionConfig) -> MarkerSeries | None:
    return read_mocap(cfg.pivot_file) if cfg.pivot_file is not None else None


def _read_bodies(cfg: SessionConfig) -> BodySeries | None:
    path = cfg.mocap.bodies_file
    if path is None:
        return None
    if detect_format(path) != "qtm_tsv_6d":
        raise BadInput(path, "mocap.bodies_file must be a QTM 6D export")
    bodies = read_qtm_6d(path)
    body = cfg.mocap.indenter_body
    if body is not None and body not in bodies.bodies:
        raise BadInput(path, f"body {body!r} (session.toml indenter_body) not in file; it has "
                             f"{', '.join(bodies.bodies)}")
    return bodies


def _read_force(cfg: SessionConfig) -> ForceSeries:
    """The force log (any layout session.toml describes), or the mocap system's analog
    channels (C3D, QTM analog TSV) or force plate (QTM force-plate TSV)."""
    return read_force(cfg.force)


def _check_shared_clock(markers: MarkerSeries, force: ForceSeries) -> None:
    """Analog channels share the mocap's clock: their rate must be a whole multiple of the
    frame rate, and they must span the same capture (within one frame)."""
    if force.meta.get("clock") != SHARED_CLOCK:
        return
    samples_per_frame(force.source, force.rate_hz, markers.rate_hz)
    span_f = _span_s(force.time_ns, force.rate_hz)       # holes count: a capture's time
    span_m = _span_s(markers.time_ns, markers.rate_hz)
    if abs(span_f - span_m) > 1.0 / markers.rate_hz:
        raise BadInput(force.source, f"the analog channels span {span_f:.3f} s but the mocap "
                                     f"export {markers.source} spans {span_m:.3f} s: not the "
                                     "same capture")


def _span_s(time_ns: np.ndarray, rate_hz: float) -> float:
    """How long a stream covers (s): its first to last sample, and the last one's period."""
    return (float(time_ns[-1] - time_ns[0]) * 1e-9 + 1.0 / rate_hz) if len(time_ns) else 0.0


def _read_calibration(cfg: SessionConfig) -> AtiCalibration | None:
    path = cfg.force.calibration
    if path is None:
        return None
    return read_ati_cal(path)


_READ = {"mocap": _read_mocap, "bodies": _read_bodies, "force": _read_force,
         "calibration": _read_calibration, "pivot": _read_pivot}


def _require_markers(markers: MarkerSeries, names: list[str]) -> None:
    have = set(markers.labels)
    absent = [n for n in names if n not in have]
    if absent:
        raise BadInput(markers.source, f"marker(s) named in session.toml not in file: "
                                       f"{', '.join(absent)}")

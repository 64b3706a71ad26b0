"""``pipeline ingest``: a raw session folder (lab files + session.toml) into one MCAP file.

Reads every file the session names with the lab readers, checks that the files agree with the
session (every named marker present, no duplicate names, the force log's named columns, a 6x6
calibration, increasing time), and writes the streams, each on its own device clock, to one
MCAP file (:mod:`data_schema.raw_mcap`) and, optionally, a rerun recording. Nothing is written
under the output names unless everything succeeds; inputs are only read.
"""

from __future__ import annotations

from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from data_schema.raw_mcap import SCHEMA, VERSION, validate_raw_mcap
from data_schema.session import ForceConfig, SessionConfig, read_session
from ingest.mcap_io import write_raw_mcap
from ingest.series import (
    AtiCalibration,
    BodySeries,
    ForceSeries,
    MarkerSeries,
    RawSession,
    check_time,
)
from pipeline.atomic import atomic_outputs
from pipeline.errors import BadInput
from pipeline.progress import progress
from pipeline.provenance import make_provenance


def ingest_session(folder: str | Path, out: str | Path, rrd: str | Path | None = None,
                   compression: str = "none") -> RawSession:
    """Read, check and store the session in ``folder``; ``rrd`` also writes the recording.

    ``compression`` of the MCAP chunks: "none" (fast) or "zstd" (about half the size).
    """
    cfg = read_session(folder)
    inputs = session_inputs(cfg)
    finals = {Path(p).resolve() for p in (out, rrd) if p is not None}
    clash = [p for p in inputs if p.resolve() in finals]
    if clash:
        raise BadInput(clash[0], "output would overwrite an input file")
    params = {"session_dir": str(folder), "out": str(out),
              "rrd": None if rrd is None else str(rrd), "compression": compression}
    # Hashing the inputs (hashlib frees the GIL) overlaps with parsing them: ~15% faster.
    with ThreadPoolExecutor(max_workers=1) as pool:
        provenance = pool.submit(make_provenance, "ingest", params, inputs, SCHEMA, VERSION)
        session = load_session(cfg)
        session.provenance = provenance.result()
    with atomic_outputs(out, rrd) as (tmp_out, tmp_rrd):
        write_raw_mcap(tmp_out, session, {"provenance": session.provenance}, compression)
        validate_raw_mcap(tmp_out, deep=False)   # blocks are checked on every read
        if tmp_rrd is not None:
            from pipeline.ingest_view import write_ingest_recording

            write_ingest_recording(session, tmp_rrd)
    return session


def session_inputs(cfg: SessionConfig) -> list[Path]:
    """Every file the session reads, session.toml first (for the provenance hashes)."""
    files = [cfg.folder / "session.toml", cfg.mocap.file, cfg.mocap.bodies_file,
             cfg.force.file, cfg.force.calibration, cfg.pivot_file]
    return [f for f in files if f is not None]


def load_session(cfg: SessionConfig) -> RawSession:
    """Read every file of the session with the lab readers and check them against it."""
    m = cfg.mocap
    steps = ["mocap", "bodies", "force", "calibration", "pivot"]
    got: dict[str, object] = {}
    with progress(steps, label="ingest: reading") as bar:
        for step in bar:
            got[step] = _READ[step](cfg)
    markers = got["mocap"]
    _require_markers(markers, m.phantom_markers + m.indenter_markers)
    if m.trigger_event and m.trigger_event not in {e for e, _ in markers.events}:
        raise BadInput(m.file, f"no EVENT labelled {m.trigger_event!r} (session.toml "
                               f"trigger_event)")
    if got["pivot"] is not None:
        _require_markers(got["pivot"], m.indenter_markers)
    return RawSession(
        name=cfg.name, markers=markers, force=got["force"],
        phantom_markers=list(m.phantom_markers), indenter_markers=list(m.indenter_markers),
        calibration=got["calibration"], bodies=got["bodies"], pivot=got["pivot"],
        trigger_event=m.trigger_event,
    )


def read_markers(path: Path) -> MarkerSeries:
    """A 3D marker export (QTM TSV, C3D or QTM MAT), checked: frames, unique names, time."""
    from ingest.detect import detect_format, read_mocap

    fmt = detect_format(path)
    if fmt == "qtm_tsv_6d":
        raise BadInput(path, "is a QTM 6D (rigid body) export; a 3D marker export is needed here")
    if fmt not in ("qtm_tsv_3d", "c3d", "qtm_mat"):
        raise BadInput(path, f"is a {fmt} file, not a 3D marker export")
    markers = read_mocap(path)
    if markers.frames == 0:
        raise BadInput(path, "holds no frames")
    _no_duplicates(path, markers.labels, "marker")
    check_time(markers.time_ns, path)
    return markers


def _read_mocap(cfg: SessionConfig) -> MarkerSeries:
    return read_markers(cfg.mocap.file)


def _read_pivot(cfg: SessionConfig) -> MarkerSeries | None:
    return read_markers(cfg.pivot_file) if cfg.pivot_file is not None else None


def _read_bodies(cfg: SessionConfig) -> BodySeries | None:
    path = cfg.mocap.bodies_file
    if path is None:
        return None
    from ingest.detect import detect_format
    from ingest.qtm_tsv import read_qtm_6d

    if detect_format(path) != "qtm_tsv_6d":
        raise BadInput(path, "mocap.bodies_file must be a QTM 6D export")
    bodies = read_qtm_6d(path)
    _no_duplicates(path, bodies.bodies, "body")
    check_time(bodies.time_ns, path)
    body = cfg.mocap.indenter_body
    if body is not None and body not in bodies.bodies:
        raise BadInput(path, f"body {body!r} (session.toml indenter_body) not in file; it has "
                             f"{', '.join(bodies.bodies)}")
    return bodies


def _read_force(cfg: SessionConfig) -> ForceSeries:
    from ingest.force_log import force_log_columns, read_force_log

    f: ForceConfig = cfg.force
    columns = force_log_columns(f.file)
    wanted = [f.time_column, *f.channels] + ([f.trigger_column] if f.trigger_column else [])
    absent = [c for c in wanted if c not in columns]
    if absent:
        raise BadInput(f.file, f"column(s) named in session.toml not in file: "
                               f"{', '.join(absent)} (it has {', '.join(map(str, columns))})")
    force = read_force_log(f.file, f.time_column, f.channels, time_unit=f.time_unit,
                           units=f.units, kind=f.kind, trigger_column=f.trigger_column)
    if force.frames == 0:
        raise BadInput(f.file, "holds no samples")
    check_time(force.time_ns, f.file)
    bad = np.flatnonzero(~np.isfinite(force.values).all(axis=1))
    if bad.size:
        raise BadInput(f.file, "missing or non-numeric value", where=f"sample {int(bad[0])}")
    return force


def _read_calibration(cfg: SessionConfig) -> AtiCalibration | None:
    path = cfg.force.calibration
    if path is None:
        return None
    from ingest.ati_cal import read_ati_cal

    cal = read_ati_cal(path)
    matrix = np.asarray(cal.matrix, dtype=float)
    if matrix.shape != (6, 6):
        raise BadInput(path, f"calibration matrix is {matrix.shape}, expected 6x6")
    if not np.isfinite(matrix).all():
        raise BadInput(path, "calibration matrix has non-finite values")
    return cal


_READ = {"mocap": _read_mocap, "bodies": _read_bodies, "force": _read_force,
         "calibration": _read_calibration, "pivot": _read_pivot}


def _require_markers(markers: MarkerSeries, names: list[str]) -> None:
    have = set(markers.labels)
    absent = [n for n in names if n not in have]
    if absent:
        raise BadInput(markers.source, f"marker(s) named in session.toml not in file: "
                                       f"{', '.join(absent)}")


def _no_duplicates(path: Path, names: list[str], what: str) -> None:
    dup = sorted(n for n, count in Counter(names).items() if count > 1)
    if dup:
        raise BadInput(path, f"duplicate {what} name(s) in file: {', '.join(dup)}")

"""Summaries of the lab's files for ``pipeline inspect``: QTM TSV 3D, 6D and analog exports,
C3D, QTM MAT, force logs (any layout :mod:`ingest.force_log` reads), ATI .cal and session.toml.

Each reads the file with its ingest reader (so a file inspect accepts, ingest reads) and
returns the summary keys that apply (:data:`ingest.inspect_stage.KEYS`); the helpers here also
summarise the series an MCAP file holds (:mod:`ingest.inspect_outputs`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from core.errors import BadInput
from core.holes import find_holes
from core.series import AtiCalibration, BodySeries, ForceSeries, MarkerSeries
from core.text import attr_text
from core.units import TIME_UNITS, time_unit_in_name, unit_to_si
from data_schema.session import SCHEMA, VERSION, ForceConfig, read_session
from ingest.ati_cal import read_ati_cal
from ingest.c3d import read_c3d, read_c3d_analog
from ingest.force_log import read_force_log, read_log_table
from ingest.force_source import read_force
from ingest.qtm_3d import read_qtm_3d
from ingest.qtm_6d import read_qtm_6d
from ingest.qtm_analog import read_qtm_analog
from ingest.qtm_mat import read_qtm_mat

TIME_NAMES = ("time", "t", "timestamp", "time_s", "times")
TRIGGER_NAMES = ("trigger", "sync")
WRENCH_NAMES = ("fx", "fy", "fz", "tx", "ty", "tz", "mx", "my", "mz")


def duration_s(time_ns: np.ndarray) -> float | None:
    """Frames x the mean sample interval (s); None for fewer than 2 samples."""
    n = int(time_ns.shape[0])
    if n < 2:
        return None
    return float((time_ns[-1] - time_ns[0]) / 1e9 * n / (n - 1))


def _series(s: MarkerSeries | BodySeries | ForceSeries) -> dict[str, Any]:
    """frames, rate, duration and holes of any series."""
    return {"frames": s.frames, "rate_hz": float(s.rate_hz), "duration_s": duration_s(s.time_ns),
            "holes": holes(s.time_ns)}


def holes(time_ns: np.ndarray) -> list[str]:
    """The holes in a stream's clock, each in words (:mod:`core.holes`); a stream whose steps
    are jitter says so instead (sync refuses it)."""
    try:
        timing = find_holes(time_ns, None)
    except BadInput as e:
        return [e.what]
    return [f"{h.length_s:.3f} s lost ({h.lost} samples) after {h.start_ns * 1e-9:.3f} s"
            for h in timing.holes]


def _events(events: list[tuple[str, int]]) -> list[list[Any]]:
    return [[label, t / 1e9] for label, t in events]


def _file_units(meta: dict[str, Any], default: str) -> str:
    """The length unit the file was written in (the readers' ``units_in_file``)."""
    unit = meta.get("units_in_file")
    return unit if isinstance(unit, str) else default


def marker_summary(m: MarkerSeries, default_units: str) -> dict[str, Any]:
    """The keys of a marker series: timing, names, missing samples, units, events."""
    return {**_series(m), "markers": list(m.labels), "missing_samples": m.missing_samples(),
            "units": {"position": _file_units(m.meta, default_units)},
            "events": _events(m.events)}


def inspect_qtm_3d(path: Path) -> dict[str, Any]:
    """A QTM TSV 3D export."""
    m = read_qtm_3d(path)
    return {**marker_summary(m, "mm"), "details": _plain(m.meta)}


def inspect_qtm_6d(path: Path) -> dict[str, Any]:
    """A QTM TSV 6D export: its bodies."""
    b = read_qtm_6d(path)
    return {**_series(b), "bodies": list(b.bodies), "missing_samples": b.missing_samples(),
            "units": {"position": _file_units(b.meta, "mm"), "rotation": "1",
                      "residual": "mm"},
            "events": _events(b.events), "details": _plain(b.meta)}


def inspect_c3d(path: Path) -> dict[str, Any]:
    """A C3D export: its markers and, when it has them, its analog channels."""
    m = read_c3d(path)
    analog = read_c3d_analog(path).summary() if m.meta.get("analog_rate") else None
    channels = [c["name"] for c in analog["channels"]] if analog else None
    return {**marker_summary(m, "mm"), "analog": analog, "channels": channels,
            "details": _plain(m.meta)}


def inspect_qtm_analog(path: Path) -> dict[str, Any]:
    """A QTM analog TSV export: its channels."""
    a = read_qtm_analog(path)
    return {"frames": a.samples, "rate_hz": a.rate_hz, "duration_s": duration_s(a.time_ns()),
            "holes": holes(a.time_ns()),
            "channels": a.names, "units": dict(zip(a.names, a.units, strict=True)),
            "analog": a.summary(), "details": _plain(a.meta)}


def inspect_qtm_mat(path: Path) -> dict[str, Any]:
    """A QTM MAT export."""
    m = read_qtm_mat(path)
    return {**marker_summary(m, "mm"), "details": _plain(m.meta)}


def inspect_force(path: Path) -> dict[str, Any]:
    """A force log (any layout). With a session.toml beside it that names it, read as the
    session says (its time unit, channels, units, scale); else guessed: the layout's time (or
    a column named like time, in the unit its name states, else s; or the rate the file
    states), a column named trigger or sync the trigger, the other numeric columns channels."""
    f, how = _session_force(path)
    if f is not None:
        return _force_summary(read_force(f), how, read_log_table(
            path, f.variable, f.delimiter, f.decimal).names)
    t = read_log_table(path)
    time = t.time or next((c for c in t.names if _bare(c) in TIME_NAMES), None)
    if time is None and t.rate_hz is None:
        raise BadInput(path, f"no time column among {', '.join(t.names[:12])} and no stated "
                             "rate: name it with force.time_column, or give force.rate_hz, in "
                             "a session.toml beside it")
    trigger = next((c for c in t.names if _bare(c) in TRIGGER_NAMES and c != time), None)
    channels = [c for c in t.names if c not in (time, trigger) and _bare(c) not in _BOOKKEEPING
                and _force_unit(t.units.get(c, "V")) and _numeric(t.columns[c])]
    if not channels:
        raise BadInput(path, f"a force log needs channels besides time, found {t.names}")
    wrench = all(_bare(c)[:2] in WRENCH_NAMES or _force_unit(t.units.get(c, "")) in
                 ("N", "N*m") for c in channels)
    unit = _integer_time_unit(t.columns[time]) if time and time != t.time and \
        time_unit_in_name(time) is None else None
    s = read_force_log(path, time, channels, time_unit=unit,
                       kind="wrench" if wrench else "gauge", trigger_column=trigger)
    how = "guessed (no session.toml beside it names this file)"
    if unit is not None:
        how += f"; whole-number times taken as {unit} (a force log at 50 Hz or more)"
    return _force_summary(s, how, t.names)


def _integer_time_unit(values: Any) -> str | None:
    """For whole-number times that state no unit: the coarsest of s, ms, us, ns in which the
    median step is a force log's rate (50 Hz or more), where s is not; None otherwise."""
    t = pd.to_numeric(pd.Series(values[:1000]), errors="coerce").to_numpy(np.float64)
    if t.size < 2 or not np.all(np.isfinite(t)) or np.any(t != np.round(t)):
        return None
    step = float(np.median(np.diff(t)))
    if step <= 0 or 1 / step >= _MIN_LOG_HZ:
        return None
    return next((u for u, ns in TIME_UNITS.items() if 1e9 / (step * ns) >= _MIN_LOG_HZ), None)


_MIN_LOG_HZ = 50.0


_BOOKKEEPING = ("sample", "status", "rdt sequence", "f/t sequence")


def _bare(name: str) -> str:
    """A column name without its bracketed unit, lower case ("Time (ms)" -> "time")."""
    return name.split("(")[0].split("[")[0].strip().lower()


def _numeric(values: Any) -> bool:
    """Whether a column's first value is a number (status words and clock text are not; a
    bad value further down is for the reader to report, with its line)."""
    head = pd.Series(values[:1] if isinstance(values, np.ndarray) else values.iloc[:1])
    return bool(pd.to_numeric(head, errors="coerce").notna().all())


def _force_unit(unit: str) -> str | None:
    try:
        return unit_to_si(unit)[1]
    except ValueError:
        return None


def _session_force(path: Path) -> tuple[ForceConfig | None, str]:
    """The [force] table of a session.toml beside ``path`` that names it, if any."""
    if not (path.parent / "session.toml").is_file():
        return None, ""
    try:
        cfg = read_session(path.parent)
    except BadInput:
        return None, ""
    if cfg.force.file.resolve() != path.resolve():
        return None, ""
    return cfg.force, "as session.toml beside it says"


def _force_summary(f: ForceSeries, how: str, columns: list[str]) -> dict[str, Any]:
    time = f.meta.get("time_column")
    return {**_series(f), "channels": list(f.channels),
            "units": {c: u for c, u in zip(f.channels, f.units, strict=True)},
            "details": {"read": how, "kind": f.kind, "columns": columns,
                        "time_column": time, "time_unit": f.meta.get("time_unit"),
                        "timed_by": f.meta.get("timed_by"),
                        **({"trigger_column": f.meta["trigger_column"]}
                           if f.meta.get("trigger_column") else {}),
                        **{k: f.meta[k] for k in ("layout", "variable", "dialect", "clock",
                                                  "units_in_file", "scale", "offset")
                           if k in f.meta}}}


def inspect_cal(path: Path) -> dict[str, Any]:
    """An ATI calibration (.cal XML)."""
    return calibration_summary(read_ati_cal(path))


def calibration_summary(c: AtiCalibration) -> dict[str, Any]:
    """The keys of an ATI calibration: its units and the matrix."""
    matrix = np.asarray(c.matrix, dtype=float)
    return {"units": {"force": c.force_units, "torque": c.torque_units},
            "calibration": {"serial": c.serial, "body_style": c.body_style,
                            "calibration": c.calibration, "matrix_shape": list(matrix.shape),
                            "matrix": matrix.tolist(),
                            "max_load": np.asarray(c.max_load, dtype=float).tolist()}}


def inspect_session(path: Path) -> dict[str, Any]:
    """A session.toml: which files it names and which markers belong to what."""
    if path.name != "session.toml":
        raise BadInput(path, "a session file must be named session.toml inside its folder")
    cfg = read_session(path.parent)
    files = {"mocap": cfg.mocap.file, "bodies": cfg.mocap.bodies_file, "force": cfg.force.file,
             "calibration": cfg.force.calibration, "pivot": cfg.pivot_file}
    return {
        "schema": cfg.raw.get("schema", SCHEMA), "schema_version": cfg.raw.get(
            "schema_version", VERSION),
        "markers": cfg.mocap.phantom_markers + cfg.mocap.indenter_markers,
        "channels": [str(c) for c in cfg.force.channels],      # names, or analog numbers
        "units": {"force_channels": ",".join(cfg.force.units), "force_time": cfg.force.time_unit},
        "details": {"name": cfg.name, "phantom_markers": len(cfg.mocap.phantom_markers),
                    "indenter_markers": cfg.mocap.indenter_markers, "force_kind": cfg.force.kind,
                    "files": {k: v.name for k, v in files.items() if v is not None},
                    **({"force_rate_hz": cfg.force.rate_hz} if cfg.force.rate_hz else {})},
    }


def plain_value(v: Any) -> Any:
    """An HDF5 or numpy value as plain text, numbers and lists."""
    if isinstance(v, bytes):
        return attr_text(v)
    if isinstance(v, np.ndarray):
        return [plain_value(x) for x in v.tolist()]
    if isinstance(v, np.generic):
        return v.item()
    return v


def _plain(meta: dict[str, Any]) -> dict[str, Any]:
    """Meta values that print and serialise as JSON."""
    return {str(k): plain_value(v) if isinstance(v, np.ndarray | np.generic | bytes) else
            (v if isinstance(v, str | int | float | bool | list | dict | None) else str(v))
            for k, v in meta.items()}

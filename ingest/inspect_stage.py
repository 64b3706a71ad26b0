"""The inspect stage runner: one summary for any lab file and any file the pipeline writes.

The summary is a dict with the same keys for every format (``None`` where a key does not apply),
so scripts can rely on them (``pipeline inspect FILE --json``):

``path``, ``format`` (the :func:`ingest.detect.detect_format` name, or ``rrd``), ``frames``,
``rate_hz``, ``duration_s`` (frames x mean sample interval), ``markers``, ``bodies``,
``channels`` (force-log channels), ``missing_samples`` (marker or body samples with no
position; None for a force log: one with a missing value is bad input), ``units`` (quantity ->
unit as stored in the file), ``events`` ([label, seconds]), ``analog`` (the analog channels of a
C3D or QTM analog TSV export: rate, samples per frame, GEN_SCALE, and per channel its number,
name, label, description, units, scale and offset), ``schema``, ``schema_version``,
``provenance`` (the stored record), ``streams`` (MCAP topic -> frames, rate_hz, names),
``datasets`` (HDF5 path -> shape, dtype, units), ``entities`` (rerun entity -> archetypes),
``calibration`` (ATI serial, matrix etc.) and ``details`` (format-specific extras: header keys,
validation result).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from core.errors import BadInput
from core.recording import rrd_entities, rrd_has_blueprint
from core.series import AtiCalibration, BodySeries, ForceSeries, MarkerSeries, RawSession
from core.text import attr_text
from data_schema.hdf5 import h5_reading
from data_schema.json_docs import (
    JSON_SCHEMAS,
    METRIC_ROWS,
    validate_folds,
    validate_json_doc,
    validate_metrics,
)
from data_schema.raw_mcap import open_reader, read_index, reading
from data_schema.registry import validator_for
from data_schema.session import SCHEMA, VERSION, read_session
from ingest.ati_cal import read_ati_cal
from ingest.c3d import read_c3d, read_c3d_analog
from ingest.detect import detect_format
from ingest.force_log import force_log_columns, read_force_log
from ingest.mcap_io import read_raw_mcap
from ingest.qtm_mat import read_qtm_mat
from ingest.qtm_tsv import read_qtm_3d, read_qtm_6d, read_qtm_analog

KEYS = ("path", "format", "frames", "rate_hz", "duration_s", "markers", "bodies", "channels",
        "missing_samples", "units", "events", "analog", "schema", "schema_version",
        "provenance", "streams", "datasets", "entities", "calibration", "details")
_SHOWN = ("format", "units_in_file")      # details already shown by the text summary
TIME_NAMES = ("time", "t", "timestamp", "time_s", "times")
TRIGGER_NAMES = ("trigger", "sync")
WRENCH_NAMES = ("fx", "fy", "fz", "tx", "ty", "tz", "mx", "my", "mz")


def run_inspect(path: str | Path) -> dict[str, Any]:
    """The summary of ``path`` (see the module doc for its keys); unknown formats are bad input."""
    path = Path(path)
    if not path.is_file():
        raise BadInput(path, "no such file")
    fmt = "rrd" if _is_rrd(path) else _detect(path)
    summary: dict[str, Any] = dict.fromkeys(KEYS)
    summary.update(path=str(path), format=fmt, details={})
    summary.update(_INSPECT[fmt](path))
    return summary


def format_summary(s: dict[str, Any]) -> str:
    """A readable multi-line text of a summary."""
    lines = [f"{s['path']}", f"  format:      {s['format']}"]
    if s["frames"] is not None:
        rate = f" at {s['rate_hz']:g} Hz" if s["rate_hz"] else ""
        dur = f" ({s['duration_s']:.3f} s)" if s["duration_s"] is not None else ""
        lines.append(f"  frames:      {s['frames']}{rate}{dur}")
    for key in ("markers", "bodies", "channels"):
        if s[key] is not None:
            lines.append(f"  {key + ':':12} {len(s[key])}: {', '.join(s[key])}")
    if s["missing_samples"] is not None:
        lines.append(f"  missing:     {s['missing_samples']} samples")
    if s["units"]:
        lines.append("  units:       " + ", ".join(f"{k} {v}" for k, v in s["units"].items()))
    if s["events"]:
        lines.append(f"  events:      {len(s['events'])}: " + ", ".join(
            f"{label} @ {t:.3f} s" for label, t in s["events"][:8]))
    if s["analog"]:
        lines += _analog_lines(s["analog"])
    if s["calibration"]:
        c = s["calibration"]
        lines.append(f"  calibration: {c['serial']} {c['body_style']} {c['calibration']}, "
                     f"matrix {c['matrix_shape']} (SI), max load {c['max_load']} N, N*m")
    if s["schema"]:
        lines.append(f"  schema:      {s['schema']} {s['schema_version']}")
    for topic, st in (s["streams"] or {}).items():
        lines.append(f"  stream:      {topic}: {st['frames']} frames at {st['rate_hz']:g} Hz, "
                     f"{len(st['names'])} names")
    for name, d in (s["datasets"] or {}).items():
        units = f" [{d['units']}]" if d["units"] else ""
        lines.append(f"  dataset:     {name} {tuple(d['shape'])} {d['dtype']}{units}")
    for entity, kinds in (s["entities"] or {}).items():
        lines.append(f"  entity:      {entity} ({', '.join(kinds)})")
    for key, value in s["details"].items():
        if key not in _SHOWN:
            lines.append(f"  {key + ':':12} {_short(value)}")
    if s["provenance"]:
        lines.append("  provenance:  " + _provenance_text(s["provenance"]))
    return "\n".join(lines)


def _analog_lines(a: dict[str, Any]) -> list[str]:
    """The analog channels, one line each: number, name, units, scale, offset."""
    per = a["samples_per_frame"]
    head = (f"  analog:      {len(a['channels'])} channels at {a['rate_hz']:g} Hz"
            + (f" ({per:g} per frame)" if per else "") + f", {a['samples']} samples, "
            f"gen. scale {a['gen_scale']:g}; values {a['values']}")
    width = max(len(c["name"]) for c in a["channels"])
    return [head] + [f"    {c['number']:3d} {c['name']:{width}}  {c['units'] or '-':4} "
                     f"scale {c['scale']:g}  offset {c['offset']:g}"
                     + (f"  (label {c['label']!r})" if c["label"] != c["name"] else "")
                     for c in a["channels"]]


def _detect(path: Path) -> str:
    fmt = detect_format(path)
    if fmt not in _INSPECT:
        raise BadInput(path, f"no summary for format {fmt!r}")
    return fmt


def _is_rrd(path: Path) -> bool:
    with open(path, "rb") as f:
        return f.read(3) == b"RRF"


def _duration(time_ns: np.ndarray) -> float | None:
    n = int(time_ns.shape[0])
    if n < 2:
        return None
    return float((time_ns[-1] - time_ns[0]) / 1e9 * n / (n - 1))


def _series(s: MarkerSeries | BodySeries | ForceSeries) -> dict[str, Any]:
    """frames, rate and duration of any series."""
    return {"frames": s.frames, "rate_hz": float(s.rate_hz), "duration_s": _duration(s.time_ns)}


def _events(events: list[tuple[str, int]]) -> list[list[Any]]:
    return [[label, t / 1e9] for label, t in events]


def _file_units(meta: dict[str, Any], default: str) -> str:
    """The length unit the file was written in (the readers' ``units_in_file``)."""
    unit = meta.get("units_in_file")
    return unit if isinstance(unit, str) else default


def _markers(m: MarkerSeries, default_units: str) -> dict[str, Any]:
    return {**_series(m), "markers": list(m.labels), "missing_samples": m.missing_samples(),
            "units": {"position": _file_units(m.meta, default_units)},
            "events": _events(m.events)}


def _inspect_qtm_3d(path: Path) -> dict[str, Any]:
    m = read_qtm_3d(path)
    return {**_markers(m, "mm"), "details": _plain(m.meta)}


def _inspect_qtm_6d(path: Path) -> dict[str, Any]:
    b = read_qtm_6d(path)
    return {**_series(b), "bodies": list(b.bodies), "missing_samples": b.missing_samples(),
            "units": {"position": _file_units(b.meta, "mm"), "rotation": "1",
                      "residual": "mm"},
            "events": _events(b.events), "details": _plain(b.meta)}


def _inspect_c3d(path: Path) -> dict[str, Any]:
    m = read_c3d(path)
    analog = read_c3d_analog(path).summary() if m.meta.get("analog_rate") else None
    return {**_markers(m, "mm"), "analog": analog, "details": _plain(m.meta)}


def _inspect_qtm_analog(path: Path) -> dict[str, Any]:
    a = read_qtm_analog(path)
    return {"frames": a.samples, "rate_hz": a.rate_hz, "duration_s": _duration(a.time_ns()),
            "channels": a.names, "units": dict(zip(a.names, a.units, strict=True)),
            "analog": a.summary(), "details": _plain(a.meta)}


def _inspect_qtm_mat(path: Path) -> dict[str, Any]:
    m = read_qtm_mat(path)
    return {**_markers(m, "mm"), "details": _plain(m.meta)}


def _inspect_force(path: Path) -> dict[str, Any]:
    """A force log without its session.toml: time is the column named like time (in s), a
    column named trigger or sync is the trigger, every other column a channel."""
    columns = [str(c) for c in force_log_columns(path)]
    time_col = next((c for c in columns if c.lower() in TIME_NAMES), columns[0])
    trigger = next((c for c in columns if c.lower() in TRIGGER_NAMES and c != time_col), None)
    channels = [c for c in columns if c not in (time_col, trigger)]
    if not channels:
        raise BadInput(path, f"a force log needs a time column and channels, found {columns}")
    wrench = all(c.lower()[:2] in WRENCH_NAMES for c in channels)
    f = read_force_log(path, time_col, channels, kind="wrench" if wrench else "gauge",
                       trigger_column=trigger)
    return {**_series(f), "channels": list(f.channels),
            "units": {c: u for c, u in zip(f.channels, f.units, strict=True)},
            "details": {"time_column": time_col, "time_unit_assumed": "s", "kind": f.kind,
                        "columns": columns,
                        **({"trigger_column": trigger} if trigger else {})}}


def _inspect_cal(path: Path) -> dict[str, Any]:
    return _calibration(read_ati_cal(path))


def _calibration(c: AtiCalibration) -> dict[str, Any]:
    matrix = np.asarray(c.matrix, dtype=float)
    return {"units": {"force": c.force_units, "torque": c.torque_units},
            "calibration": {"serial": c.serial, "body_style": c.body_style,
                            "calibration": c.calibration, "matrix_shape": list(matrix.shape),
                            "matrix": matrix.tolist(),
                            "max_load": np.asarray(c.max_load, dtype=float).tolist()}}


def _inspect_mcap(path: Path) -> dict[str, Any]:
    s: RawSession = read_raw_mcap(path)            # every block checked on the way
    with reading(path), open(path, "rb") as f:
        index = read_index(open_reader(f, path), path)
    session = index.records["session"]
    out = _markers(s.markers, "m")
    out.update(
        channels=list(s.force.channels), bodies=None if s.bodies is None else s.bodies.bodies,
        schema=session["schema"], schema_version=session["schema_version"],
        provenance=s.provenance,
        streams={t: {"frames": c.frames, "rate_hz": c.rate_hz, "names": c.names,
                     "source": c.source} for t, c in index.channels.items()},
        units={"position": "m", "time": "ns",
               **dict(zip(s.force.channels, s.force.units, strict=True))},
        details={"session": s.name, "phantom_markers": len(s.phantom_markers),
                 "indenter_markers": len(s.indenter_markers), "force_kind": s.force.kind,
                 "force_clock": s.force.meta.get("clock", "own (force log)"),
                 "trigger_event": s.trigger_event},
    )
    if s.calibration is not None:
        out["calibration"] = _calibration(s.calibration)["calibration"]
    return out


def _inspect_hdf5(path: Path) -> dict[str, Any]:
    """Root attributes and every dataset, read generically (any schema, ours or not)."""
    with h5_reading(path), h5py.File(path, "r") as f:
        attrs = {k: _attr(v) for k, v in f.attrs.items()}
        datasets: dict[str, dict[str, Any]] = {}
        f.visititems(lambda name, obj: datasets.update({name: _dataset(obj)})
                     if isinstance(obj, h5py.Dataset) else None)
        times = sorted((n for n in datasets if n.rsplit("/", 1)[-1] in ("time_ns", "time")),
                       key=lambda n: (n.count("/"), n))
        timing = _h5_timing(f[times[0]]) if times else {}
        missing = sum(_nan_points(f[n]) for n, d in datasets.items()
                      if d["units"] == "m" and d["shape"][-1:] == [3])
    schema = attrs.pop("schema", None)
    version = attrs.pop("schema_version", None)
    provenance = attrs.pop("provenance", None)
    names = next((attrs.pop(k) for k in ("markers", "point_names", "labels") if k in attrs), None)
    return {**timing, "schema": schema, "schema_version": version,
            "provenance": _json_or_text(provenance), "datasets": datasets,
            "markers": list(names) if isinstance(names, list | tuple) else None,
            "missing_samples": missing,
            "units": {n: d["units"] for n, d in datasets.items() if d["units"]},
            "details": {"attributes": attrs, "valid": _validity(path, schema)}}


def _dataset(obj: Any) -> dict[str, Any]:
    units = obj.attrs.get("units")
    return {"shape": list(obj.shape), "dtype": str(obj.dtype),
            "units": None if units is None else _attr(units)}


def _h5_timing(ds: Any) -> dict[str, Any]:
    t = np.asarray(ds[()], dtype=np.float64)
    if t.ndim != 1 or t.size == 0:
        return {}
    t_ns = t if ds.name.endswith("time_ns") else t * 1e9
    dt = np.median(np.diff(t_ns)) if t.size > 1 else np.nan
    return {"frames": int(t.size), "rate_hz": float(1e9 / dt) if dt > 0 else None,
            "duration_s": _duration(t_ns.astype(np.int64))}


def _nan_points(ds: Any, rows: int = 1 << 16) -> int:
    """Points with no position in a ``(..., 3)`` float dataset, read in slabs."""
    if ds.dtype.kind != "f" or ds.ndim < 2:
        return 0
    return sum(int(np.isnan(ds[i:i + rows]).any(axis=-1).sum())
               for i in range(0, ds.shape[0], rows))


def _validity(path: Path, schema: str | None) -> str | None:
    check = validator_for(schema) if schema else None
    if check is None:
        return None
    return _valid(lambda: check(path))


def _inspect_json(path: Path) -> dict[str, Any]:
    try:
        doc = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise BadInput(path, f"not valid JSON ({e})") from None
    if isinstance(doc, list):
        return {"details": {"items": len(doc)}}
    if not isinstance(doc, dict):
        return {"details": {"value": _short(doc)}}
    details = {"keys": sorted(k for k in doc if k != "provenance")}
    if doc.get("schema") == "phantom.folds":
        details["valid"] = _valid(lambda: validate_folds(path))
        details["folds"] = [{r: len(f[r]["groups"]) for r in ("train", "val", "test")
                             if isinstance(f, dict) and isinstance(f.get(r), dict)}
                            for f in doc.get("folds", [])]
    elif doc.get("schema") in JSON_SCHEMAS:
        details["valid"] = _valid(lambda: validate_json_doc(path, JSON_SCHEMAS[doc["schema"]]))
    elif set(METRIC_ROWS) <= set(doc):
        details["valid"] = _valid(lambda: validate_metrics(path))
    return {"schema": doc.get("schema"), "schema_version": doc.get("schema_version"),
            "provenance": doc.get("provenance"), "details": details}


def _valid(check: Callable[[], object]) -> str:
    try:
        check()
    except BadInput as e:
        return f"invalid: {e.what}"
    return "valid"


def _inspect_session(path: Path) -> dict[str, Any]:
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


def _inspect_rrd(path: Path) -> dict[str, Any]:
    try:
        entities = rrd_entities(path)
        blueprint = rrd_has_blueprint(path)
    except Exception as e:  # rerun raises its own error types for a damaged file
        raise BadInput(path, f"not a readable rerun recording ({e})") from None
    return {"entities": {e: sorted(a) for e, a in sorted(entities.items())},
            "details": {"blueprint": blueprint}}


def _attr(v: Any) -> Any:
    if isinstance(v, bytes):
        return attr_text(v)
    if isinstance(v, np.ndarray):
        return [_attr(x) for x in v.tolist()]
    if isinstance(v, np.generic):
        return v.item()
    return v


def _json_or_text(v: Any) -> Any:
    if isinstance(v, str):
        try:
            return json.loads(v)
        except json.JSONDecodeError:
            return v
    return v


def _plain(meta: dict[str, Any]) -> dict[str, Any]:
    """Meta values that print and serialise as JSON."""
    return {str(k): _attr(v) if isinstance(v, np.ndarray | np.generic | bytes) else
            (v if isinstance(v, str | int | float | bool | list | dict | None) else str(v))
            for k, v in meta.items()}


def _short(value: Any, limit: int = 200) -> str:
    """One line of text: dicts as ``key value; ...``, lists space-separated, cut at ``limit``."""
    if isinstance(value, dict):
        text = "; ".join(f"{k} {_short(v, limit)}" for k, v in value.items())
    elif isinstance(value, list | tuple):
        text = " ".join(_short(v, limit) for v in value)
    else:
        text = value if isinstance(value, str) else json.dumps(value, default=str)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _provenance_text(p: Any) -> str:
    if not isinstance(p, dict):
        return _short(p)
    head = ", ".join(f"{k} {p[k]}" for k in ("stage", "code_version", "created") if p.get(k))
    inputs = p.get("inputs") or {}
    files = "; ".join(f"{Path(k).name} sha256 {str(v)[:12]}" for k, v in inputs.items())
    return head + (f"; inputs: {files}" if files else "")


_INSPECT: dict[str, Callable[[Path], dict[str, Any]]] = {
    "qtm_tsv_3d": _inspect_qtm_3d, "qtm_tsv_6d": _inspect_qtm_6d, "c3d": _inspect_c3d,
    "qtm_tsv_analog": _inspect_qtm_analog,
    "qtm_mat": _inspect_qtm_mat, "force_csv": _inspect_force, "force_mat": _inspect_force,
    "force_parquet": _inspect_force, "ati_cal": _inspect_cal, "mcap": _inspect_mcap,
    "hdf5": _inspect_hdf5, "json": _inspect_json, "rrd": _inspect_rrd,
    "session_toml": _inspect_session,
}

"""Summaries of the files the pipeline writes, for ``pipeline inspect``: raw MCAP (every block
checked on the way), HDF5 of any schema (ours validated), JSON documents (fold manifests,
fit-msm's constants, metrics: validated) and rerun recordings.
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
from core.series import RawSession
from core.text import one_line
from data_schema.hdf5 import h5_reading
from data_schema.json_docs import FOLDS
from data_schema.raw_mcap import open_reader, read_index, reading
from data_schema.registry import json_validator_for, validator_for
from ingest.inspect_lab import calibration_summary, duration_s, marker_summary, plain_value
from ingest.mcap_io import read_raw_mcap


def inspect_mcap(path: Path) -> dict[str, Any]:
    """Ingest's MCAP: the session's series, topics, calibration and provenance."""
    s: RawSession = read_raw_mcap(path)            # every block checked on the way
    with reading(path), open(path, "rb") as f:
        index = read_index(open_reader(f, path), path)
    session = index.records["session"]
    out = marker_summary(s.markers, "m")
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
        out["calibration"] = calibration_summary(s.calibration)["calibration"]
    return out


def inspect_hdf5(path: Path) -> dict[str, Any]:
    """Root attributes and every dataset, read generically (any schema, ours or not)."""

    with h5_reading(path), h5py.File(path, "r") as f:
        attrs = {k: plain_value(v) for k, v in f.attrs.items()}
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
            "units": None if units is None else plain_value(units)}


def _h5_timing(ds: Any) -> dict[str, Any]:
    t = np.asarray(ds[()], dtype=np.float64)
    if t.ndim != 1 or t.size == 0:
        return {}
    t_ns = t if ds.name.endswith("time_ns") else t * 1e9
    dt = np.median(np.diff(t_ns)) if t.size > 1 else np.nan
    return {"frames": int(t.size), "rate_hz": float(1e9 / dt) if dt > 0 else None,
            "duration_s": duration_s(t_ns.astype(np.int64))}


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


def inspect_json(path: Path) -> dict[str, Any]:
    """A JSON document: its keys; ours (manifests, fit-msm's constants, metrics) checked."""
    try:
        doc = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise BadInput(path, f"not valid JSON ({e})") from None
    if isinstance(doc, list):
        return {"details": {"items": len(doc)}}
    if not isinstance(doc, dict):
        return {"details": {"value": one_line(doc)}}
    details: dict[str, Any] = {"keys": sorted(k for k in doc if k != "provenance")}
    check = json_validator_for(doc)
    if check is not None:
        details["valid"] = _valid(lambda: check(path))
    if doc.get("schema") == FOLDS.name:
        details["folds"] = [{r: len(f[r]["groups"]) for r in ("train", "val", "test")
                             if isinstance(f, dict) and isinstance(f.get(r), dict)}
                            for f in doc.get("folds", [])]
    return {"schema": doc.get("schema"), "schema_version": doc.get("schema_version"),
            "provenance": doc.get("provenance"), "details": details}


def _valid(check: Callable[[], object]) -> str:
    try:
        check()
    except BadInput as e:
        return f"invalid: {e.what}"
    return "valid"


def inspect_rrd(path: Path) -> dict[str, Any]:
    """A rerun recording: its entities and whether it has a blueprint."""
    try:
        entities = rrd_entities(path)
        blueprint = rrd_has_blueprint(path)
    except Exception as e:  # rerun raises its own error types for a damaged file
        raise BadInput(path, f"not a readable rerun recording ({e})") from None
    return {"entities": {e: sorted(a) for e, a in sorted(entities.items())},
            "details": {"blueprint": blueprint}}


def _json_or_text(v: Any) -> Any:
    if isinstance(v, str):
        try:
            return json.loads(v)
        except json.JSONDecodeError:
            return v
    return v

"""Write and read the raw-session MCAP file (layout: :mod:`data_schema.raw_mcap`).

Each stream keeps its own device clock; values are stored as float64 blocks of about one second,
so a 10-minute 500 Hz session (245 MB of arrays) writes in a fraction of a second and reads back
bit-identical. Chunks are uncompressed by default: zstd (level 3, all the MCAP library offers)
halves the file but took 2.3-3 s for that session, more than parsing the TSV itself.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from core.atomic import atomic_output
from core.provenance import code_version
from core.series import (
    AtiCalibration,
    BodySeries,
    ForceSeries,
    MarkerSeries,
    RawSession,
    check_time,
)
from core.text import to_json
from data_schema.raw_mcap import (
    BLOCK_SECONDS,
    RAW_MCAP,
    SCHEMA,
    VERSION,
    Channel,
    encode_block,
    iter_blocks,
    open_reader,
    read_index,
    reading,
)
from ingest.ingest_params import COMPRESSIONS

CHUNK_BYTES = 1 << 20   # 1 MiB chunks


@dataclass
class _Stream:
    """One channel to write: times, per-sample arrays (leading axis = time), names."""

    topic: str
    time_ns: np.ndarray
    arrays: tuple[np.ndarray, ...]
    names: list[str]
    rate_hz: float
    source: str
    units: list[str] | None = None


def write_raw_mcap(path: str | Path, session: RawSession, metadata: dict[str, Any],
                   compression: str) -> None:
    """Write ``session`` to ``path`` (atomically) as one MCAP file of raw streams.

    ``metadata`` holds extra metadata records by name, each a dict of JSON-able values; its
    ``provenance`` record (default: ``session.provenance``) should come from
    :func:`core.provenance.make_provenance`. ``compression``: "none" or "zstd" chunks.
    """
    from mcap.writer import CompressionType, Writer

    if compression not in COMPRESSIONS:
        raise ValueError(f"compression must be one of {COMPRESSIONS}, got {compression!r}")
    streams = _streams(session)
    records = {"session": _session_record(session)}
    if session.calibration is not None:
        records["calibration"] = _calibration_record(session.calibration)
    records["provenance"] = dict(session.provenance)
    records.update(metadata)
    missing = [k for k in RAW_MCAP.metadata["provenance"] if k not in records["provenance"]]
    if missing:
        raise ValueError(f"provenance record lacks {missing}: pass make_provenance(...)")
    with atomic_output(path) as tmp, open(tmp, "wb") as f:
        writer = Writer(f, chunk_size=CHUNK_BYTES, compression=CompressionType[compression.upper()])
        writer.start(profile="", library=f"phantom-pipeline {code_version()}")
        for s in streams:
            _write_stream(writer, s)
        for name, record in records.items():
            writer.add_metadata(name, {k: to_json(v) for k, v in record.items()})
        writer.finish()


def read_raw_mcap(path: str | Path) -> RawSession:
    """Read an MCAP written by :func:`write_raw_mcap`; a bad or damaged file is bad input."""
    with reading(path), open(path, "rb") as f:
        reader = open_reader(f, path)
        index = read_index(reader, path)
        data = {t: (np.empty(c.frames, dtype=np.int64), np.empty((c.frames, c.k)))
                for t, c in index.channels.items()}
        for info, start, times, values in iter_blocks(reader, index, path):
            t, v = data[info.topic]
            t[start:start + times.shape[0]] = times
            v[start:start + times.shape[0]] = values
        return _session(index.records, data)   # inside the guard: a record may lack a key


def _session(rec: dict[str, dict[str, Any]],
             data: dict[str, tuple[np.ndarray, np.ndarray]]) -> RawSession:
    """The session from the metadata records and the decoded channels."""
    s = rec["session"]
    force_t, force_v = data["/force/raw"]
    trigger = data.get("/force/trigger")
    return RawSession(
        name=s["name"],
        markers=_markers(s["mocap"], data, "/mocap"),
        force=ForceSeries(
            source=s["force"]["source"], time_ns=force_t, channels=s["force"]["names"],
            values=force_v, units=s["force"]["units"], kind=s["force"]["kind"],
            rate_hz=s["force"]["rate_hz"], trigger=None if trigger is None else trigger[1][:, 0],
            meta=s["force"]["meta"],
        ),
        phantom_markers=s["phantom_markers"], indenter_markers=s["indenter_markers"],
        calibration=_calibration(rec["calibration"]) if "calibration" in rec else None,
        bodies=_bodies(s["bodies"], data) if s["bodies"] is not None else None,
        pivot=_markers(s["pivot"], data, "/pivot") if s["pivot"] is not None else None,
        trigger_event=s["trigger_event"], phantom=s.get("phantom"),
        provenance=rec["provenance"],
    )


def _streams(session: RawSession) -> list[_Stream]:
    """The channels of a session, in the order they are written."""
    out = _marker_streams(session.markers, "/mocap")
    if session.bodies is not None:
        b = session.bodies
        out.append(_Stream("/mocap/bodies", b.time_ns, (b.positions, b.rotations, b.residuals),
                           list(b.bodies), b.rate_hz, b.source))
    if session.pivot is not None:
        out += _marker_streams(session.pivot, "/pivot")
    f = session.force
    out.append(_Stream("/force/raw", f.time_ns, (f.values,), list(f.channels), f.rate_hz,
                       f.source, list(f.units)))
    if f.trigger is not None:
        out.append(_Stream("/force/trigger", f.time_ns, (f.trigger,), ["trigger"], f.rate_hz,
                           f.source))
    for s in out:
        check_time(s.time_ns, s.source)
        k = _channel(s.topic).values_per_sample(len(s.names))
        got = sum(int(np.prod(a.shape[1:])) for a in s.arrays)
        if any(a.shape[0] != s.time_ns.shape[0] for a in s.arrays) or got != k:
            raise ValueError(f"{s.topic}: arrays {[a.shape for a in s.arrays]} do not match "
                             f"{s.time_ns.shape[0]} samples of {len(s.names)} names")
    return out


def _marker_streams(m: MarkerSeries, prefix: str) -> list[_Stream]:
    out = [_Stream(f"{prefix}/markers", m.time_ns, (m.positions,), list(m.labels), m.rate_hz,
                   m.source)]
    if m.residuals is not None:
        out.append(_Stream(f"{prefix}/residuals", m.time_ns, (m.residuals,), list(m.labels),
                           m.rate_hz, m.source))
    return out


def _channel(topic: str) -> Channel:
    """The raw MCAP's layout of the stream ``topic`` (one of its own topics)."""
    spec = RAW_MCAP.channel(topic)
    if spec is None:
        raise ValueError(f"{topic}: no stream of the raw MCAP layout")
    return spec


def _block_samples(rate_hz: float) -> int:
    return max(1, round(rate_hz * BLOCK_SECONDS)) if np.isfinite(rate_hz) else 1


def _write_stream(writer: Any, s: _Stream) -> None:
    spec = _channel(s.topic)
    block = _block_samples(s.rate_hz)
    frames = int(s.time_ns.shape[0])
    meta = {"names": json.dumps(s.names), "frames": str(frames), "block_samples": str(block),
            "rate_hz": repr(float(s.rate_hz)), "source": str(s.source)}
    if s.units is not None:
        meta["units"] = json.dumps(s.units)
    schema_id = writer.register_schema(spec.schema_name, spec.encoding, spec.layout_json())
    cid = writer.register_channel(s.topic, spec.encoding, schema_id, meta)
    for seq, start in enumerate(range(0, frames, block)):
        stop = min(frames, start + block)
        parts = [a[start:stop].reshape(stop - start, -1) for a in s.arrays]
        values = parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)
        t0 = max(0, int(s.time_ns[start]))
        writer.add_message(cid, t0, encode_block(s.time_ns[start:stop], values), t0,
                           sequence=seq)


def _session_record(s: RawSession) -> dict[str, Any]:
    f = s.force
    return {
        "schema": SCHEMA, "schema_version": VERSION, "name": s.name,
        "phantom_markers": list(s.phantom_markers), "indenter_markers": list(s.indenter_markers),
        "trigger_event": s.trigger_event, "phantom": s.phantom,
        "mocap": _marker_desc(s.markers),
        "force": {"source": str(f.source), "rate_hz": float(f.rate_hz), "frames": f.frames,
                  "names": list(f.channels), "units": list(f.units), "kind": f.kind,
                  "trigger": f.trigger is not None, "meta": f.meta},
        "bodies": None if s.bodies is None else {
            "source": str(s.bodies.source), "rate_hz": float(s.bodies.rate_hz),
            "frames": s.bodies.frames, "names": list(s.bodies.bodies),
            "events": _events(s.bodies.events), "meta": s.bodies.meta},
        "pivot": None if s.pivot is None else _marker_desc(s.pivot),
    }


def _marker_desc(m: MarkerSeries) -> dict[str, Any]:
    return {"source": str(m.source), "rate_hz": float(m.rate_hz), "frames": m.frames,
            "names": list(m.labels), "events": _events(m.events),
            "residuals": m.residuals is not None, "meta": m.meta}


def _events(events: list[tuple[str, int]]) -> list[list[Any]]:
    return [[str(label), int(t)] for label, t in events]


def _calibration_record(c: AtiCalibration) -> dict[str, Any]:
    return {"source": str(c.source), "serial": c.serial, "body_style": c.body_style,
            "calibration": c.calibration, "matrix": np.asarray(c.matrix, float).tolist(),
            "max_load": np.asarray(c.max_load, float).tolist(), "force_units": c.force_units,
            "torque_units": c.torque_units, "meta": c.meta}


def _markers(desc: dict[str, Any], data: dict[str, tuple[np.ndarray, np.ndarray]],
             prefix: str) -> MarkerSeries:
    t, v = data[f"{prefix}/markers"]
    res = data.get(f"{prefix}/residuals")
    return MarkerSeries(
        source=desc["source"], time_ns=t, labels=desc["names"],
        positions=v.reshape(t.shape[0], len(desc["names"]), 3), rate_hz=desc["rate_hz"],
        residuals=None if res is None else res[1], events=[(e, int(n)) for e, n in
                                                          desc["events"]],
        meta=desc["meta"],
    )


def _bodies(desc: dict[str, Any], data: dict[str, tuple[np.ndarray, np.ndarray]]
            ) -> BodySeries:
    t, v = data["/mocap/bodies"]
    n, b = t.shape[0], len(desc["names"])
    return BodySeries(
        source=desc["source"], time_ns=t, bodies=desc["names"],
        positions=v[:, :3 * b].reshape(n, b, 3),
        rotations=v[:, 3 * b:12 * b].reshape(n, b, 3, 3),
        residuals=v[:, 12 * b:], rate_hz=desc["rate_hz"],
        events=[(e, int(x)) for e, x in desc["events"]], meta=desc["meta"],
    )


def _calibration(r: dict[str, Any]) -> AtiCalibration:
    return AtiCalibration(
        source=r["source"], serial=r["serial"], body_style=r["body_style"],
        calibration=r["calibration"], matrix=np.asarray(r["matrix"], dtype=float),
        max_load=np.asarray(r["max_load"], dtype=float), force_units=r["force_units"],
        torque_units=r["torque_units"], meta=r.get("meta", {}),
    )


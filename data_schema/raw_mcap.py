"""``X.mcap`` from ``pipeline ingest``: the raw lab streams, each on its own device clock.

One MCAP file (1 MiB chunks, uncompressed or zstd, with summary, chunk indexes, statistics and
chunk CRCs) holds every stream of a session exactly as the lab files had it, converted to SI
units but neither synchronised nor calibrated. Each stream is one or two channels; ``log_time`` and
``publish_time`` of a message are the device time (ns) of the block's first sample (clipped at
0, since MCAP times are unsigned; the exact, signed times are inside the message).

Message layout ``phantom.block`` version 1 (all little-endian): one message holds a block of
consecutive samples (``block_samples`` of them, 1 s of data; the last block may be shorter)::

    offset 0    char[4]   magic  b"PBLK"
    offset 4    uint16    layout version (1)
    offset 6    uint16    flags (0)
    offset 8    uint32    n  samples in this block
    offset 12   uint32    k  float64 values per sample
    offset 16   int64[n]  time_ns of each sample, on the device clock, strictly increasing
    then        float64[n, k]  values, sample-major; a sample is the channel's fields in order,
                          each flattened in C order (e.g. markers: x, y, z of marker 0, then 1..)

Message ``sequence`` numbers count the blocks of a channel from 0, so block ``s`` starts at
sample ``s * block_samples``. Missing values (mocap gaps, lost bodies) are NaN.

Channel metadata (all text): ``names`` (JSON list binding the channel's named size: marker
labels, body names or force channels), ``frames`` (total samples), ``block_samples``,
``rate_hz``, ``source`` (the lab file) and, for ``/force/raw``, ``units`` (JSON list, one per
channel). The schema record of each channel (encoding ``phantom.block``) is this layout as JSON.

Metadata records (each value is JSON text): ``session`` (schema, schema_version, name,
phantom_markers, indenter_markers, trigger_event, and one description per stream: ``mocap``,
``force``, ``bodies``, ``pivot`` with source, rate_hz, frames, names, units, events, meta;
optionally ``phantom``, session.toml's layout, :mod:`data_schema.phantom`),
``calibration`` (the ATI matrix etc.; required when force kind is ``gauge``) and ``provenance``
(from ``make_provenance``: stage, code version, command, parameters, input sha256s).
"""

from __future__ import annotations

import contextlib
import json
import math
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from core.errors import BadInput

SCHEMA = "phantom.raw_mcap"
VERSION = "1.0"
ENCODING = "phantom.block"          # message encoding and schema encoding of every channel
BLOCK_MAGIC = b"PBLK"
BLOCK_VERSION = 1
BLOCK_HEADER = struct.Struct("<4sHHII")   # magic, layout version, flags, n samples, k values
BLOCK_SECONDS = 1.0                 # nominal duration of one message

Dim = int | str


@dataclass(frozen=True)
class Field:
    """One quantity of a sample; ``shape`` may use the channel's named size."""

    name: str
    shape: tuple[Dim, ...]
    units: str | None           # None: one unit per name, from the channel's ``units`` metadata
    dtype: str = "f8"
    doc: str = ""
    finite: bool = False        # NaN refused too (inf always is: a gap is NaN)
    limit: float | None = None  # largest plausible |value| in ``units`` (catches mm, mN)


@dataclass(frozen=True)
class Channel:
    """One MCAP channel: topic, schema, encoding, per-sample fields, rate."""

    topic: str
    schema_name: str
    fields: tuple[Field, ...]
    rate: str
    required: bool = False
    dim: str | None = None       # the named size that ``names`` binds (M, B, C)
    encoding: str = ENCODING
    doc: str = ""

    def values_per_sample(self, names: int) -> int:
        """``k`` of the block layout for a channel with ``names`` names."""
        sizes: dict[Dim, int] = {self.dim: names} if self.dim else {}
        return sum(math.prod(d if isinstance(d, int) else sizes[d] for d in f.shape)
                   for f in self.fields)

    def layout_json(self) -> bytes:
        """The schema record's data: this channel's block layout, self-described."""
        return json.dumps({
            "layout": ENCODING, "version": BLOCK_VERSION, "header": BLOCK_HEADER.format,
            "header_fields": ["magic", "version", "flags", "n", "k"],
            "time": "int64[n] ns", "values": "float64[n, k] sample-major",
            "fields": [{"name": f.name, "shape": list(f.shape), "units": f.units or "per name"}
                       for f in self.fields],
            "names_bind": self.dim, "rate": self.rate,
        }).encode()


@dataclass(frozen=True)
class McapLayout:
    """A versioned MCAP layout: its channels and its metadata records with their keys."""

    name: str
    version: str
    channels: tuple[Channel, ...]
    metadata: dict[str, tuple[str, ...]] = field(default_factory=dict)
    doc: str = ""

    def channel(self, topic: str) -> Channel | None:
        return next((c for c in self.channels if c.topic == topic), None)


LAB_M = 50.0        # no marker of a mocap volume lies this far from its origin
RESIDUAL_M = 1.0    # a marker residual of a metre is no fit at all (mm written as m)
UNIT_LIMITS = {"N": 1000.0, "N*m": 100.0}   # per-name units: beyond any phantom press
_POSITION = Field("position", ("M", 3), "m", doc="x, y, z in the mocap frame; NaN in a gap",
                  limit=LAB_M)
_RESIDUAL = Field("residual", ("M",), "m", doc="QTM residual of each marker; NaN in a gap",
                  limit=RESIDUAL_M)
_MOCAP_RATE = "mocap frame rate (QTM FREQUENCY; 500 Hz in the lab)"

RAW_MCAP = McapLayout(
    name=SCHEMA,
    version=VERSION,
    doc=__doc__ or "",
    channels=(
        Channel("/mocap/markers", "phantom.raw.MarkerPositions", (_POSITION,), _MOCAP_RATE,
                required=True, dim="M", doc="every labelled marker of the trial's 3D export"),
        Channel("/mocap/residuals", "phantom.raw.MarkerResiduals", (_RESIDUAL,), _MOCAP_RATE,
                dim="M", doc="residuals, when the export has them (C3D)"),
        Channel("/mocap/bodies", "phantom.raw.BodyPoses", (
            Field("position", ("B", 3), "m", doc="body origin in the mocap frame", limit=LAB_M),
            Field("rotation", ("B", 3, 3), "1", doc="rotation matrix, body to lab, row-major",
                  limit=1.0 + 1e-6),
            Field("residual", ("B",), "m", doc="QTM residual; NaN when the body is lost",
                  limit=RESIDUAL_M),
        ), _MOCAP_RATE, dim="B", doc="QTM 6D export of the indenter, when present"),
        Channel("/pivot/markers", "phantom.raw.MarkerPositions", (_POSITION,), _MOCAP_RATE,
                dim="M", doc="pivot-calibration recording, when present"),
        Channel("/pivot/residuals", "phantom.raw.MarkerResiduals", (_RESIDUAL,), _MOCAP_RATE,
                dim="M", doc="its residuals, when the export has them"),
        Channel("/force/raw", "phantom.raw.ForceChannels",
                (Field("value", ("C",), None, doc="gauge volts or calibrated Fx..Tz",
                       finite=True),),
                "force logger rate (1 kHz Speedgoat)", required=True, dim="C",
                doc="the six force-log channels as logged"),
        Channel("/force/trigger", "phantom.raw.Trigger",
                (Field("trigger", (1,), "1", doc="sync/trigger channel as logged",
                       finite=True),),
                "force logger rate", doc="the logger's trigger column, when logged"),
    ),
    metadata={
        "session": ("schema", "schema_version", "name", "phantom_markers", "indenter_markers",
                    "trigger_event", "mocap", "force", "bodies", "pivot"),
        "calibration": ("source", "serial", "body_style", "calibration", "matrix", "max_load",
                        "force_units", "torque_units"),
        "provenance": ("stage", "code_version", "inputs"),
    },
)

# Which stream description of the ``session`` record each channel belongs to.
STREAM_OF_TOPIC = {
    "/mocap/markers": "mocap", "/mocap/residuals": "mocap", "/mocap/bodies": "bodies",
    "/pivot/markers": "pivot", "/pivot/residuals": "pivot",
    "/force/raw": "force", "/force/trigger": "force",
}
MAIN_TOPIC = {"mocap": "/mocap/markers", "bodies": "/mocap/bodies", "pivot": "/pivot/markers",
              "force": "/force/raw"}
CHANNEL_KEYS = ("names", "frames", "block_samples", "rate_hz", "source")


def encode_block(time_ns: np.ndarray, values: np.ndarray) -> bytes:
    """One message: header, ``n`` int64 times, ``n x k`` float64 values (little-endian)."""
    n = int(time_ns.shape[0])
    k = int(values.shape[1]) if values.ndim == 2 else 0
    head = BLOCK_HEADER.pack(BLOCK_MAGIC, BLOCK_VERSION, 0, n, k)
    return b"".join((head, np.ascontiguousarray(time_ns, dtype="<i8").tobytes(),
                     np.ascontiguousarray(values, dtype="<f8").tobytes()))


def decode_block(data: bytes, k: int, path: str | Path, where: str
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Times ``(n,)`` and values ``(n, k)`` of one message (views on ``data``, no copy)."""
    if len(data) < BLOCK_HEADER.size:
        raise BadInput(path, "message shorter than the block header", where=where)
    magic, version, _flags, n, kk = BLOCK_HEADER.unpack_from(data)
    if magic != BLOCK_MAGIC or version != BLOCK_VERSION:
        raise BadInput(path, f"not a {ENCODING} v{BLOCK_VERSION} message "
                             f"(magic {magic!r}, version {version})", where=where)
    if kk != k:
        raise BadInput(path, f"message has {kk} values per sample, channel needs {k}",
                       where=where)
    if len(data) != BLOCK_HEADER.size + 8 * n * (1 + k):
        raise BadInput(path, f"message of {len(data)} bytes does not hold {n} samples",
                       where=where)
    times = np.frombuffer(data, dtype="<i8", count=n, offset=BLOCK_HEADER.size)
    values = np.frombuffer(data, dtype="<f8", offset=BLOCK_HEADER.size + 8 * n).reshape(n, k)
    return times, values


@dataclass
class ChannelInfo:
    """What the summary says about one channel, checked against the layout."""

    id: int
    topic: str
    spec: Channel
    names: list[str]
    frames: int
    block_samples: int
    rate_hz: float
    source: str
    units: list[str] | None
    blocks: int

    @property
    def k(self) -> int:
        return self.spec.values_per_sample(len(self.names))

    def value_rules(self) -> tuple[list[str], np.ndarray, np.ndarray]:
        """Per value of a sample: its label, whether NaN is refused, its plausible limit."""
        labels, finite, limit = [], [], []
        for f in self.spec.fields:
            sizes = [len(self.names) if d == self.spec.dim else int(d) for d in f.shape]
            for idx in np.ndindex(*sizes):
                named = self.names[idx[0]] if f.shape[0] == self.spec.dim else idx[0]
                unit = f.units or (self.units[idx[0]] if self.units else "")
                labels.append(f"{f.name} {named}" + "".join(f"[{i}]" for i in idx[1:]))
                finite.append(f.finite)
                limit.append(f.limit or UNIT_LIMITS.get(unit, np.inf))
        return labels, np.array(finite), np.array(limit)


@dataclass
class RawMcapIndex:
    """The checked summary of a raw MCAP file: metadata records and channels by topic."""

    records: dict[str, dict[str, Any]]
    channels: dict[str, ChannelInfo]


ERRORS: tuple[type[Exception], ...] = (ValueError, KeyError, IndexError, TypeError, EOFError,
                                       AttributeError, OSError, struct.error, UnicodeDecodeError)


@contextlib.contextmanager
def reading(path: str | Path) -> Iterator[None]:
    """Turn any decoding failure of the MCAP library into :class:`BadInput` naming ``path``."""
    from mcap.exceptions import McapError
    from zstandard import ZstdError

    errors: tuple[type[Exception], ...] = (McapError, ZstdError, *ERRORS)
    try:
        yield
    except BadInput:
        raise
    except errors as e:
        raise BadInput(path, f"not a readable raw MCAP file ({type(e).__name__}: {e})") from None


def open_reader(stream: IO[bytes], path: str | Path):  # noqa: ANN201 - mcap's SeekingReader
    """A CRC-checking MCAP reader; the file must start with the MCAP magic."""
    from mcap.reader import make_reader

    if stream.read(8) != b"\x89MCAP0\r\n":
        raise BadInput(path, "not an MCAP file (bad magic)")
    stream.seek(0)
    return make_reader(stream, validate_crcs=True)


def read_index(reader: Any, path: str | Path) -> RawMcapIndex:
    """Check the summary, metadata and channels against :data:`RAW_MCAP`; no message is read."""
    summary = reader.get_summary()
    if summary is None or summary.statistics is None:
        raise BadInput(path, "truncated or incomplete MCAP file (no summary section)")
    records = {m.name: {k: json.loads(v) for k, v in m.metadata.items()}
               for m in reader.iter_metadata()}
    _check_records(path, records)
    counts = summary.statistics.channel_message_counts
    channels: dict[str, ChannelInfo] = {}
    for cid, ch in summary.channels.items():
        info = _channel(path, ch, summary.schemas.get(ch.schema_id), counts.get(cid, 0))
        if info.topic in channels:
            raise BadInput(path, f"channel {info.topic} appears twice")
        channels[info.topic] = info
    for spec in RAW_MCAP.channels:
        if spec.required and spec.topic not in channels:
            raise BadInput(path, f"missing channel {spec.topic}")
    _check_streams(path, records["session"], channels)
    return RawMcapIndex(records, channels)


def iter_blocks(reader: Any, index: RawMcapIndex, path: str | Path
                ) -> Iterator[tuple[ChannelInfo, int, np.ndarray, np.ndarray]]:
    """``(channel, first sample, times, values)`` of every message, in file order.

    Each block is checked (header, sample count for its sequence number, increasing times);
    after the last one, every block of every channel must have been seen exactly once and time
    must increase from block to block.
    """
    by_id = {c.id: c for c in index.channels.values()}
    rules = {t: c.value_rules() for t, c in index.channels.items()}
    spans: dict[str, dict[int, tuple[int, int]]] = {t: {} for t in index.channels}
    for _schema, ch, msg in reader.iter_messages(log_time_order=False):
        info = by_id[ch.id]
        where = f"{info.topic} block {msg.sequence}"
        times, values = decode_block(msg.data, info.k, path, where)
        start = msg.sequence * info.block_samples
        expect = min(info.block_samples, info.frames - start)
        if msg.sequence in spans[info.topic] or msg.sequence >= info.blocks or \
                times.shape[0] != expect:
            raise BadInput(path, f"unexpected block of {times.shape[0]} samples", where=where)
        if times.size > 1 and not (np.diff(times) > 0).all():
            raise BadInput(path, "time is not increasing", where=where)
        _check_values(path, values, rules[info.topic], where)
        spans[info.topic][msg.sequence] = (int(times[0]), int(times[-1]))
        yield info, start, times, values
    for topic, blocks in spans.items():
        if len(blocks) != index.channels[topic].blocks:
            raise BadInput(path, f"{topic} has {len(blocks)} of "
                                 f"{index.channels[topic].blocks} blocks")
        for seq in range(1, len(blocks)):
            if blocks[seq][0] <= blocks[seq - 1][1]:
                raise BadInput(path, "time is not increasing", where=f"{topic} block {seq}")


def _check_values(path: str | Path, values: np.ndarray,
                  rules: tuple[list[str], np.ndarray, np.ndarray], where: str) -> None:
    """No inf; no NaN where a field is finite; nothing beyond a field's plausible limit."""
    labels, finite, limit = rules
    bad = np.isinf(values) | (np.isnan(values) & finite)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise BadInput(path, f"sample {i}: {labels[j]} is {values[i, j]} (not a finite value)",
                       where=where)
    over = np.abs(np.nan_to_num(values)) > limit
    if over.any():
        i, j = np.argwhere(over)[0]
        raise BadInput(path, f"sample {i}: {labels[j]} is {values[i, j]:.4g}, more than a "
                             f"plausible {limit[j]:g} in SI units: millimetres or millinewtons?",
                       where=where)


def validate_raw_mcap(path: str | Path, deep: bool = True) -> RawMcapIndex:
    """Raise :class:`BadInput` naming the first way ``path`` departs from :data:`RAW_MCAP`.

    Checks the summary, metadata records and channels (schemas, encodings, names, units, and
    message counts against frames and block size). ``deep`` also decodes every block header
    and its times (values are not copied), so damage inside a chunk is caught (chunk CRCs).
    """
    with reading(path), open(path, "rb") as f:
        reader = open_reader(f, path)
        index = read_index(reader, path)
        if deep:
            for _ in iter_blocks(reader, index, path):
                pass
    return index


def _check_records(path: str | Path, records: dict[str, dict[str, Any]]) -> None:
    for name, keys in RAW_MCAP.metadata.items():
        if name == "calibration" and records.get("session", {}).get("force", {}).get(
                "kind") != "gauge":
            continue
        if name not in records:
            raise BadInput(path, f"missing metadata record {name!r}")
        missing = [k for k in keys if k not in records[name]]
        if missing:
            raise BadInput(path, f"metadata record {name!r} lacks {missing}")
    session = records["session"]
    if session["schema"] != SCHEMA:
        raise BadInput(path, f"schema is {session['schema']!r}, expected {SCHEMA!r}")
    if str(session["schema_version"]).split(".")[0] != VERSION.split(".")[0]:
        raise BadInput(path, f"schema version {session['schema_version']} is not compatible "
                             f"with {VERSION}")
    if "calibration" in records:
        shape = np.asarray(records["calibration"]["matrix"], dtype=float).shape
        if shape != (6, 6):
            raise BadInput(path, f"calibration matrix is {shape}, expected (6, 6)")


def _channel(path: str | Path, ch: Any, schema: Any, count: int) -> ChannelInfo:
    spec = RAW_MCAP.channel(ch.topic)
    if spec is None:
        raise BadInput(path, f"unknown channel {ch.topic}")
    if ch.message_encoding != spec.encoding or schema is None or \
            schema.name != spec.schema_name or schema.encoding != spec.encoding:
        raise BadInput(path, f"channel {ch.topic} is not {spec.schema_name} in {spec.encoding}")
    missing = [k for k in CHANNEL_KEYS if k not in ch.metadata]
    if missing:
        raise BadInput(path, f"channel {ch.topic} lacks metadata {missing}")
    meta = ch.metadata
    names = json.loads(meta["names"])
    units = json.loads(meta["units"]) if "units" in meta else None
    info = ChannelInfo(
        id=ch.id, topic=ch.topic, spec=spec, names=names, frames=int(meta["frames"]),
        block_samples=int(meta["block_samples"]), rate_hz=float(meta["rate_hz"]),
        source=meta["source"], units=units, blocks=count,
    )
    if info.block_samples < 1 or info.frames < 0:
        raise BadInput(path, f"channel {ch.topic} has bad frames/block_samples")
    if count != -(-info.frames // info.block_samples):
        raise BadInput(path, f"channel {ch.topic} has {count} messages for {info.frames} "
                             f"frames in blocks of {info.block_samples}")
    if spec.fields[0].units is None and (units is None or len(units) != len(names)):
        raise BadInput(path, f"channel {ch.topic} needs one unit per name")
    return info


def _check_streams(path: str | Path, session: dict[str, Any],
                   channels: dict[str, ChannelInfo]) -> None:
    """Each channel agrees with its stream's description in the ``session`` record."""
    for stream, topic in MAIN_TOPIC.items():
        if session.get(stream) is not None and topic not in channels:
            raise BadInput(path, f"session record describes {stream!r} but {topic} is missing")
    for topic, info in channels.items():
        desc = session.get(STREAM_OF_TOPIC[topic])
        if not isinstance(desc, dict):
            raise BadInput(path, f"channel {topic} has no {STREAM_OF_TOPIC[topic]!r} "
                                 f"description in the session record")
        if int(desc["frames"]) != info.frames:
            raise BadInput(path, f"channel {topic} has {info.frames} frames, session record "
                                 f"says {desc['frames']}")
        if topic != "/force/trigger" and list(desc["names"]) != info.names:
            raise BadInput(path, f"channel {topic} names differ from the session record")

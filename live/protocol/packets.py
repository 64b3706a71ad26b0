"""The QTM real-time protocol's wire format, both ways: every packet encoded (what the replay
sends), decoded (what the live client reads), and a reader that splits a TCP byte stream into
packets.

Written from QTM's real-time protocol documentation, whose layout is this (the vendor's client,
``qtm-rt``, is what the replay is tested against). Everything is little-endian (QTM's port
22223). Every packet::

    u32 size        the whole packet, these 8 bytes included
    u32 type        0 error, 1 command, 2 XML, 3 data, 4 no more data, 6 event
    payload         size - 8 bytes

Payloads: a command, error or XML text ends in one NUL byte; an event is one byte, its code;
"no more data" is empty; a data packet (a frame) is::

    i64 timestamp   microseconds
    u32 frame number
    u32 component count
    components      each: u32 size (these 8 bytes included), u32 type, then its body

Component bodies (markers in mm, float32, NaN when lost):

- 3D (1): u32 marker count, u16 2D drop rate, u16 out-of-sync rate, then x, y, z (f32) of
  each marker in the order of the 3D labels;
- 3D without labels (2): the same header, then x, y, z (f32) and u32 id of each marker seen;
- analog (3): u32 device count; per device u32 id, u32 channel count, u32 sample count, and
  only when the sample count is not 0 the u32 number of its first sample, then the f32 values
  channel after channel (all samples of channel 1, then of channel 2, ...);
- force (4): u32 plate count; per plate u32 id, u32 force count, u32 number of its first
  force, then each force as 9 f32 (force x, y, z, moment x, y, z, point of application x, y,
  z).

Pure functions on bytes: numpy arrays in, ``bytes`` out, and back. Bytes that do not follow
this layout (a size below its header's, a count that runs past the end) are a
:class:`ProtocolError`, whatever the field.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import NamedTuple

import numpy as np

HEADER = struct.Struct("<II")              # size (header included), type
DATA_HEADER = struct.Struct("<qII")        # timestamp (us), frame number, component count
COMPONENT = struct.Struct("<II")           # size (header included), type
MARKERS = struct.Struct("<IHH")            # marker count, 2D drop rate, out-of-sync rate
COUNT = struct.Struct("<I")                # analog devices, force plates
DEVICE = struct.Struct("<III")             # id, channel count, sample count
PLATE = struct.Struct("<III")              # id, force count, first force's number
NUMBER = struct.Struct("<I")               # an analog device's first sample number
FORCE_VALUES = 9                           # force x y z, moment x y z, application point x y z
MAX_PACKET = 1 << 24                       # a larger size is no packet of ours: 16 MiB


class PacketType(IntEnum):
    """The packet types of the protocol (5, a C3D file, and 7+ are not served)."""

    ERROR = 0
    COMMAND = 1
    XML = 2
    DATA = 3
    NO_MORE_DATA = 4
    EVENT = 6


class Component(IntEnum):
    """The data components served (of the protocol's 19)."""

    THREE_D = 1
    THREE_D_NO_LABELS = 2
    ANALOG = 3
    FORCE = 4


class Event(IntEnum):
    """QTM's event codes (one byte in an event packet)."""

    CONNECTED = 1
    CONNECTION_CLOSED = 2
    CAPTURE_STARTED = 3
    CAPTURE_STOPPED = 4
    CALIBRATION_STARTED = 6
    CALIBRATION_STOPPED = 7
    RT_FROM_FILE_STARTED = 8
    RT_FROM_FILE_STOPPED = 9
    WAITING_FOR_TRIGGER = 10
    CAMERA_SETTINGS_CHANGED = 11
    QTM_SHUTTING_DOWN = 12
    CAPTURE_SAVED = 13
    REPROCESSING_STARTED = 14
    REPROCESSING_STOPPED = 15
    TRIGGER = 16


class Packet(NamedTuple):
    """One packet read off the stream: its type (an int: an unknown type is kept as read) and
    its payload (the bytes after the 8-byte header)."""

    type: int
    payload: bytes


class ProtocolError(Exception):
    """Bytes that are not QTM RT packets: a packet's size below its header's or beyond
    :data:`MAX_PACKET`, a data packet whose components or counts run past its end.
    ``packets``: those the same bytes completed before the damage (:meth:`PacketReader.feed`),
    which a reader still hands on."""

    def __init__(self, message: str, packets: Sequence[Packet] = ()) -> None:
        super().__init__(message)
        self.packets = list(packets)


@dataclass(frozen=True)
class AnalogBlock:
    """One analog device's samples in a frame: ``values`` (samples, channels), the first
    one's ``first_sample`` number."""

    device_id: int
    first_sample: int
    values: np.ndarray


@dataclass(frozen=True)
class ForceBlock:
    """One force plate's forces in a frame: ``values`` (forces, 9), the first one's number."""

    plate_id: int
    first_force: int
    values: np.ndarray


def _packet(kind: PacketType, payload: bytes) -> bytes:
    return HEADER.pack(HEADER.size + len(payload), kind) + payload


def encode_text(kind: PacketType, text: str) -> bytes:
    """A command, error or XML packet: ``text`` in UTF-8 and its NUL."""
    if kind not in (PacketType.COMMAND, PacketType.ERROR, PacketType.XML):
        raise ValueError(f"{kind!r} carries no text")
    return _packet(kind, text.encode("utf-8") + b"\0")


def encode_command(text: str) -> bytes:
    """A command packet (type 1): a client's command, or a server's plain reply."""
    return encode_text(PacketType.COMMAND, text)


def encode_error(text: str) -> bytes:
    """An error packet (type 0): the server refuses the last command."""
    return encode_text(PacketType.ERROR, text)


def encode_xml(text: str) -> bytes:
    """An XML packet (type 2): the answer to GetParameters."""
    return encode_text(PacketType.XML, text)


def encode_no_more_data() -> bytes:
    """A "no more data" packet (type 4): no payload."""
    return _packet(PacketType.NO_MORE_DATA, b"")


def encode_event(event: Event) -> bytes:
    """An event packet (type 6): one byte, the event's code."""
    return _packet(PacketType.EVENT, bytes([Event(event)]))


def encode_data(timestamp_us: int, frame: int, components: Sequence[bytes]) -> bytes:
    """A data packet (type 3) of one frame from its encoded ``components``."""
    body = DATA_HEADER.pack(timestamp_us, frame, len(components)) + b"".join(components)
    return _packet(PacketType.DATA, body)


def _component(kind: Component, body: bytes) -> bytes:
    return COMPONENT.pack(COMPONENT.size + len(body), kind) + body


def encode_3d(markers_mm: np.ndarray) -> bytes:
    """The 3D component: ``markers_mm`` (M, 3) in mm, NaN where lost, in the labels' order
    (drop rates 0)."""
    xyz = np.ascontiguousarray(markers_mm, dtype="<f4").reshape(-1, 3)
    return _component(Component.THREE_D, MARKERS.pack(len(xyz), 0, 0) + xyz.tobytes())


def encode_3d_no_labels(markers_mm: np.ndarray, ids: np.ndarray) -> bytes:
    """The 3D-without-labels component: the markers seen, ``markers_mm`` (M, 3) in mm, each
    with its ``ids`` (M,) number (drop rates 0)."""
    xyz = np.asarray(markers_mm, dtype="<f4").reshape(-1, 3)
    rows = np.empty(len(xyz), dtype=[("xyz", "<f4", 3), ("id", "<u4")])
    rows["xyz"], rows["id"] = xyz, ids
    return _component(Component.THREE_D_NO_LABELS,
                      MARKERS.pack(len(xyz), 0, 0) + rows.tobytes())


def encode_analog(devices: Sequence[AnalogBlock]) -> bytes:
    """The analog component: per device its header, the first sample's number when it has
    samples, then the values channel after channel."""
    parts = [COUNT.pack(len(devices))]
    for d in devices:
        values = np.asarray(d.values, dtype="<f4")
        if values.ndim != 2:
            raise ValueError(f"analog values must be (samples, channels), got {values.shape}")
        n, channels = values.shape
        parts.append(DEVICE.pack(d.device_id, channels, n))
        if n:
            parts += [NUMBER.pack(d.first_sample), np.ascontiguousarray(values.T).tobytes()]
    return _component(Component.ANALOG, b"".join(parts))


def encode_force(plates: Sequence[ForceBlock]) -> bytes:
    """The force component: per plate its header, then its forces (9 f32 each)."""
    parts = [COUNT.pack(len(plates))]
    for p in plates:
        values = np.ascontiguousarray(p.values, dtype="<f4").reshape(-1, FORCE_VALUES)
        parts += [PLATE.pack(p.plate_id, len(values), p.first_force), values.tobytes()]
    return _component(Component.FORCE, b"".join(parts))


@dataclass(frozen=True)
class DataPacket:
    """A data packet's payload read: its timestamp (us), frame number and the body of each of
    its components by type (views into the payload, without their 8-byte headers)."""

    timestamp_us: int
    frame: int
    components: dict[int, memoryview]


def decode_data(payload: bytes) -> DataPacket:
    """A data packet's payload (the bytes after the packet's header) split into components."""
    timestamp, frame, count = _unpack(DATA_HEADER, payload, 0, "a data packet's header")
    view, pos, bodies = memoryview(payload), DATA_HEADER.size, {}
    for _ in range(count):
        size, kind = _unpack(COMPONENT, payload, pos, f"frame {frame}: a component's header")
        if size < COMPONENT.size or pos + size > len(payload):
            raise ProtocolError(f"frame {frame}: a component of {size} bytes past the packet's "
                                "end")
        bodies[kind] = view[pos + COMPONENT.size:pos + size]
        pos += size
    return DataPacket(timestamp, frame, bodies)


def decode_3d(body: bytes | memoryview) -> np.ndarray:
    """The 3D component's markers (M, 3) in mm, float32, NaN where lost."""
    n = _unpack(MARKERS, body, 0, "the 3D component")[0]
    return _floats(body, MARKERS.size, (n, 3), "the 3D component's markers")


def decode_3d_no_labels(body: bytes | memoryview) -> tuple[np.ndarray, np.ndarray]:
    """The 3D-without-labels component: the markers seen (M, 3) in mm, float32, and their
    ids (M,)."""
    n = _unpack(MARKERS, body, 0, "the 3D-without-labels component")[0]
    rows = np.dtype([("xyz", "<f4", 3), ("id", "<u4")])
    if MARKERS.size + n * rows.itemsize > len(body):
        raise ProtocolError(f"the 3D-without-labels component: {n} markers past its end")
    got = np.frombuffer(body, rows, count=n, offset=MARKERS.size)
    return got["xyz"], got["id"]


def decode_analog(body: bytes | memoryview) -> list[AnalogBlock]:
    """The analog component's devices, each its samples (samples, channels) and the first
    one's number (0 where it has none this frame)."""
    (devices,), pos, blocks = _unpack(COUNT, body, 0, "the analog component"), COUNT.size, []
    for _ in range(devices):
        device, channels, samples = _unpack(DEVICE, body, pos, "an analog device's header")
        pos += DEVICE.size
        first = 0
        if samples:
            (first,), pos = _unpack(NUMBER, body, pos, "an analog device's first sample"), \
                pos + NUMBER.size
        values = _floats(body, pos, (channels, samples), f"analog device {device}'s samples")
        blocks.append(AnalogBlock(device, first, values.T))
        pos += 4 * channels * samples
    return blocks


def decode_force(body: bytes | memoryview) -> list[ForceBlock]:
    """The force component's plates, each its forces (forces, 9) and the first one's number."""
    (plates,), pos, blocks = _unpack(COUNT, body, 0, "the force component"), COUNT.size, []
    for _ in range(plates):
        plate, forces, first = _unpack(PLATE, body, pos, "a force plate's header")
        pos += PLATE.size
        values = _floats(body, pos, (forces, FORCE_VALUES), f"force plate {plate}'s forces")
        blocks.append(ForceBlock(plate, first, values))
        pos += 4 * FORCE_VALUES * forces
    return blocks


def decode_event(payload: bytes) -> int:
    """An event packet's code (an int: a code this module does not name is kept as read)."""
    if len(payload) != 1:
        raise ProtocolError(f"an event of {len(payload)} bytes (one, its code, expected)")
    return payload[0]


def _unpack(layout: struct.Struct, data: bytes | memoryview, pos: int, what: str) -> tuple:
    if pos + layout.size > len(data):
        raise ProtocolError(f"{what} past the end ({len(data) - pos} of {layout.size} bytes)")
    return layout.unpack_from(data, pos)


def _floats(data: bytes | memoryview, pos: int, shape: tuple[int, int], what: str
            ) -> np.ndarray:
    """``shape`` little-endian float32 at ``pos``, a view of ``data``."""
    n = shape[0] * shape[1]
    if pos + 4 * n > len(data):
        raise ProtocolError(f"{what} past the end ({n} values, {len(data) - pos} bytes left)")
    return np.frombuffer(data, "<f4", count=n, offset=pos).reshape(shape)


def text_of(payload: bytes) -> str:
    """A command, error or XML payload as text, without its NUL."""
    return payload.split(b"\0", 1)[0].decode("utf-8", "replace")


class PacketReader:
    """Splits a TCP byte stream into packets: :meth:`feed` the bytes as they arrive and get
    the packets completed so far; a truncated packet waits for the rest."""

    def __init__(self, max_size: int = MAX_PACKET) -> None:
        self._buffer = bytearray()
        self._max_size = max_size

    @property
    def pending(self) -> int:
        """Bytes received that complete no packet yet."""
        return len(self._buffer)

    def feed(self, data: bytes) -> list[Packet]:
        """The packets that ``data`` completes, in order; :class:`ProtocolError` where a
        header states an impossible size (with the packets completed before it)."""
        self._buffer += data
        packets: list[Packet] = []
        start = 0
        while len(self._buffer) - start >= HEADER.size:
            size, kind = HEADER.unpack_from(self._buffer, start)
            if not HEADER.size <= size <= self._max_size:
                del self._buffer[:start]
                raise ProtocolError(f"packet of {size} bytes (type {kind}): not a QTM RT "
                                    "packet", packets)
            if len(self._buffer) - start < size:
                break
            packets.append(Packet(kind, bytes(self._buffer[start + HEADER.size:start + size])))
            start += size
        del self._buffer[:start]
        return packets

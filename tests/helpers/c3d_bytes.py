"""Reading and patching the parameter section of an Intel C3D file byte by byte, as the C3D
format describes it (independently of ezc3d and of ingest.c3d), for tests that spoil one
parameter of a real export or check a reader against the raw data."""

from __future__ import annotations

import struct
from collections.abc import Iterator
from pathlib import Path

import numpy as np


def _records(data: bytes) -> Iterator[tuple[int, int, str, int]]:
    """(record start, group id, name, link position) of every parameter and group record."""
    pos = (data[0] - 1) * 512 + 4
    while True:
        n = abs(struct.unpack_from("b", data, pos)[0])
        if n == 0:
            return
        gid = struct.unpack_from("b", data, pos + 1)[0]
        link = pos + 2 + n
        yield pos, gid, data[pos + 2:link].decode(), link
        step = struct.unpack_from("<h", data, link)[0]
        if step == 0:
            return
        pos = link + step


def _find(data: bytes, group: str, name: str) -> tuple[int, int]:
    """(record start, link position) of parameter ``group:name``."""
    groups = {-gid: label for _, gid, label, _ in _records(data) if gid < 0}
    for pos, gid, label, link in _records(data):
        if gid > 0 and groups.get(gid) == group and label == name:
            return pos, link
    raise KeyError(f"{group}:{name}")


def c3d_parameter(data: bytes, group: str, name: str) -> tuple[int, int]:
    """(byte offset of the value, type) of a parameter (its first value for an array)."""
    _, link = _find(data, group, name)
    kind, dims = struct.unpack_from("bB", data, link + 2)
    return link + 4 + dims, kind


def set_parameter(data: bytearray, group: str, name: str, value: float, index: int = 0) -> None:
    """Write ``value`` into element ``index`` of a numeric parameter, in its own type."""
    offset, kind = c3d_parameter(bytes(data), group, name)
    fmt = {4: "<f", 2: "<h", 1: "<b"}[kind]
    struct.pack_into(fmt, data, offset + index * kind, value)


def rename_parameter(data: bytearray, group: str, name: str, new: str) -> None:
    """Give parameter ``group:name`` another name of the same length (so it reads as absent)."""
    assert len(new) == len(name)
    pos, _ = _find(bytes(data), group, name)
    data[pos + 2:pos + 2 + len(name)] = new.encode()


def float_frames(data: bytes, data_block: int, values_per_frame: int, frames: int) -> np.ndarray:
    """The data section of a float-format C3D as (frames, values per frame) float32 numbers."""
    start = (data_block - 1) * 512
    raw = np.frombuffer(data[start:start + 4 * values_per_frame * frames], dtype="<f4")
    return raw.reshape(frames, values_per_frame)


# The real Qualisys C3D of ../shared/real_samples (relative to it), and what it holds.
QUALISYS_C3D = Path("c3d") / "qualisys_55markers_200hz.c3d"
POINTS, CHANNELS, PER_FRAME, FRAMES = 55, 69, 10, 340


def qualisys_analog(data: bytes) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Raw analog samples (T, C), SCALE, OFFSET and GEN_SCALE of the real export, read straight
    from its bytes: float data, each 3D frame's 4 x 55 point values then 10 x 69 samples."""
    block = int(np.frombuffer(data, "<u2", 1, 16)[0])               # header word 9
    frames = float_frames(data, block, 4 * POINTS + PER_FRAME * CHANNELS, FRAMES)
    raw = frames[:, 4 * POINTS:].reshape(FRAMES * PER_FRAME, CHANNELS).astype(np.float64)
    scale = np.frombuffer(data, "<f4", CHANNELS, c3d_parameter(data, "ANALOG", "SCALE")[0])
    offset = np.frombuffer(data, "<i2", CHANNELS, c3d_parameter(data, "ANALOG", "OFFSET")[0])
    gen = np.frombuffer(data, "<f4", 1, c3d_parameter(data, "ANALOG", "GEN_SCALE")[0])[0]
    return raw, scale.astype(np.float64), offset.astype(np.float64), float(gen)

"""C3D exports (QTM, Vicon, ...) through ezc3d: 3D points, residuals, labels, rate and events.

ezc3d gives points as ``(4, N, T)`` in ``POINT:UNITS`` and residuals as ``(1, N, T)``; a negative
residual marks a missing sample. We return metres, NaN where missing, time 0 at the first frame.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any

import numpy as np

from core.errors import BadInput
from core.series import MarkerSeries, frame_times_ns, time_to_ns
from core.units import length_scale


def _param(params: dict, group: str, name: str, path: str | Path) -> Any:
    try:
        return params[group][name]["value"]
    except KeyError:
        raise BadInput(path, f"C3D parameter {group}:{name} is missing") from None


def _first(params: dict, group: str, name: str, path: str | Path) -> Any:
    """The first value of a parameter (RATE, UNITS); an empty one is bad input."""
    values = np.ravel(_param(params, group, name, path))
    if values.size == 0:
        raise BadInput(path, f"C3D parameter {group}:{name} is empty")
    return values[0]


def _labels(params: dict, n: int, path: str | Path) -> list[str]:
    """POINT:LABELS, continued in LABELS2, LABELS3 ... when there are more than 255 points."""
    labels = [str(s).strip() for s in _param(params, "POINT", "LABELS", path)]
    k = 2
    while len(labels) < n and f"LABELS{k}" in params["POINT"]:
        labels += [str(s).strip() for s in params["POINT"][f"LABELS{k}"]["value"]]
        k += 1
    labels = labels[:n]
    if len(labels) < n or any(not s for s in labels):
        raise BadInput(path, f"POINT:LABELS names {len(labels)} of {n} points")
    dups = sorted({s for s in labels if labels.count(s) > 1})
    if dups:
        raise BadInput(path, f"duplicate point label(s): {', '.join(dups)}")
    return labels


def _events(params: dict, start_s: float, path: str | Path) -> list[tuple[str, int]]:
    """EVENT:LABELS at EVENT:TIMES ([minutes; seconds] from the trial start), on our clock."""
    ev = params.get("EVENT", {})
    if "LABELS" not in ev or "TIMES" not in ev:
        return []
    labels = [str(s).strip() for s in ev["LABELS"]["value"]]
    times = np.asarray(ev["TIMES"]["value"], dtype=np.float64).reshape(2, -1)
    ns = time_to_ns(times[0] * 60.0 + times[1] - start_s, path, where=lambda i: f"event {i}")
    return [(lab, int(t)) for lab, t in zip(labels, ns, strict=False)]


def _check_header(path: str | Path) -> int | None:
    """Check the file against its own header before ezc3d reads it; return the frame count.

    The header (block 1) says where the parameter section starts (byte 0: its first 512-byte
    block), the section's first 4 bytes its length in blocks (byte 2) and the processor type
    (byte 3: 84 Intel, 85 DEC, 86 MIPS big-endian), and header word 9 the block where the data
    starts. ezc3d reads past the end of a file cut before those points (it crashed or hung on
    such files), so a file shorter than they say is refused as truncated here. The frame count
    comes from the header words (ezc3d rewrites its copy to what it read, so a truncated data
    section would pass unnoticed); None when the header cannot say (> 65535 frames).
    """
    size = Path(path).stat().st_size
    with open(path, "rb") as f:
        head = f.read(512)
        start = (head[0] - 1) * 512 if head else 0
        if start < 512:
            raise BadInput(path, "not a C3D file: the header points to no parameter section")
        f.seek(start)
        param = f.read(4)
    if len(head) < 512 or len(param) < 4:
        raise BadInput(path, f"truncated: {size} bytes end before the parameter section")
    order = ">" if param[3] == 86 else "<"
    params_end = start + param[2] * 512
    data_start = (int(np.frombuffer(head[16:18], dtype=f"{order}u2")[0]) - 1) * 512
    if size < params_end:
        raise BadInput(path, f"truncated: {size} bytes end inside the parameter section "
                             f"(bytes {start} to {params_end})")
    if size < data_start:
        raise BadInput(path, f"truncated: {size} bytes end before the data section (byte "
                             f"{data_start})")
    with open(path, "rb") as f:
        f.seek(start)
        _check_parameters(path, f.read(params_end - start), order, start)
    first, last = np.frombuffer(head[6:10], dtype=f"{order}u2")
    if last >= 65535 or last < first:
        return None
    return int(last) - int(first) + 1


def _check_parameters(path: str | Path, section: bytes, order: str, offset: int) -> None:
    """Walk the parameter records as ezc3d will, refusing any that would lead it astray.

    A record: name length (int8, negative when locked; 0 ends the section), group id (int8),
    the name, the int16 offset from that field to the next record (0: the last), then a group's
    description or a parameter's type (int8: -1 char, 1 byte, 2 int16, 4 float), dimension
    count, dimensions (uint8 each), data and description. ezc3d trusts these numbers; a damaged
    one made it crash or loop, so each record must fit before the next, and the next must lie
    ahead, inside the section.
    """
    pos = 4
    while pos + 2 <= len(section):
        n = abs(struct.unpack_from("b", section, pos)[0])
        if n == 0:
            return
        group = struct.unpack_from("b", section, pos + 1)[0] < 0
        link = pos + 2 + n
        if link + 2 > len(section):
            break
        step = struct.unpack_from(order + "h", section, link)[0]
        end = link + 2
        if not group and end + 2 <= len(section):
            kind, dims = struct.unpack_from("bB", section, end)
            shape = section[end + 2:end + 2 + dims]
            end += 2 + dims + abs(kind) * (int(np.prod(list(shape))) if dims else 1)
        if end < len(section):
            end += 1 + section[end]                                   # the description
        nxt = link + step
        if step < 0 or end > len(section) or (step and nxt < end):
            raise BadInput(path, "damaged parameter section: a record does not fit where "
                                 "the next one starts", where=f"byte {offset + pos}")
        if step == 0:
            return
        pos = nxt
    raise BadInput(path, "damaged parameter section: records run past its end",
                   where=f"byte {offset + pos}")


def read_c3d(path: str | Path) -> MarkerSeries:
    """Read the 3D points of a C3D file: metres, NaN where the residual is negative."""
    import ezc3d

    if not Path(path).is_file():
        raise BadInput(path, "no such file")
    claimed = _check_header(path)
    try:
        c = ezc3d.c3d(str(path))
    except Exception as e:  # ezc3d raises bare RuntimeError/IndexError/... on bad files
        raise BadInput(path, f"not a readable C3D file ({e})") from None
    params = c["parameters"]
    points = np.asarray(c["data"]["points"], dtype=np.float64)          # (4, N, T)
    residuals = np.asarray(c["data"]["meta_points"]["residuals"], dtype=np.float64)
    if points.ndim != 3 or points.shape[0] < 3:
        raise BadInput(path, f"C3D points have shape {points.shape}, expected (4, N, T)")
    n_points, n_frames = points.shape[1], points.shape[2]
    if claimed is not None and claimed != n_frames:
        raise BadInput(path, f"truncated: the header says {claimed} frames but {n_frames} "
                             "could be read", where=f"frame {n_frames}")
    rate = _first(params, "POINT", "RATE", path)
    if not isinstance(rate, int | float | np.number):
        raise BadInput(path, f"POINT:RATE {rate!r} is not a number")
    rate = float(rate)
    time_ns = frame_times_ns(n_frames, rate, path, "POINT:RATE")
    units = str(_first(params, "POINT", "UNITS", path)).strip()
    try:
        scale = length_scale(units)
    except ValueError as e:
        raise BadInput(path, f"POINT:UNITS {e}") from None
    labels = _labels(params, n_points, path)

    positions = points[:3].transpose(2, 1, 0) * scale                   # (T, N, 3)
    res = residuals.reshape(n_points, n_frames).T * scale               # (T, N)
    missing = (res < 0) | np.isnan(res) | np.isnan(positions).any(axis=2)
    positions[missing] = np.nan
    res[missing] = np.nan
    first_frame = int(c["header"]["points"]["first_frame"])             # 0-based in ezc3d
    meta = {
        "format": "c3d", "units_in_file": units, "first_frame": first_frame,
        "analog_rate": float(c["header"]["analogs"]["frame_rate"]),
    }
    events = _events(params, first_frame / rate, path)
    return MarkerSeries(source=str(path), time_ns=time_ns, labels=labels, positions=positions,
                        rate_hz=rate, residuals=res, events=events, meta=meta)

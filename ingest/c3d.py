"""C3D exports (QTM, Vicon, ...) through ezc3d: 3D points, residuals, labels, rate and events.

ezc3d gives points as ``(4, N, T)`` in ``POINT:UNITS`` and residuals as ``(1, N, T)``; a negative
residual marks a missing sample. We return metres, NaN where missing, time 0 at the first frame.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from core.errors import BadInput
from core.series import MarkerSeries, frame_times_ns, time_to_ns
from core.units import length_scale
from ingest.analog import AnalogExport, check_scales, samples_per_frame


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
    """POINT:LABELS, continued in LABELS2, LABELS3 ... when there are more than 255 points.

    Exactly ``n`` names: a label more than the data hold names a marker whose data are not in
    the file (empty padding after the ``n`` names is allowed)."""
    labels = [str(s).strip() for s in _param(params, "POINT", "LABELS", path)]
    k = 2
    while f"LABELS{k}" in params["POINT"]:
        labels += [str(s).strip() for s in params["POINT"][f"LABELS{k}"]["value"]]
        k += 1
    extra = [s for s in labels[n:] if s]
    if extra:
        raise BadInput(path, f"POINT:LABELS names {n + len(extra)} points but POINT:USED and "
                             f"the data hold {n} (no data for {', '.join(extra[:3])}"
                             f"{' ...' if len(extra) > 3 else ''})")
    labels = labels[:n]
    if len(labels) < n or any(not s for s in labels):
        raise BadInput(path, f"POINT:LABELS names {sum(map(bool, labels))} of {n} points")
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
    times = np.asarray(ev["TIMES"]["value"], dtype=np.float64)
    used = _count(params, "EVENT", "USED", path)
    if times.ndim != 2 or times.shape[0] != 2 or times.shape[1] != len(labels) or (
            used is not None and used != len(labels)):
        said = "" if used is None else f", EVENT:USED says {used}"
        raise BadInput(path, f"EVENT:TIMES has shape {times.shape} for {len(labels)} "
                             f"EVENT:LABELS{said}: times and names must pair up (2 x events)")
    ns = time_to_ns(times[0] * 60.0 + times[1] - start_s, path, where=lambda i: f"event {i}")
    return [(lab, int(t)) for lab, t in zip(labels, ns, strict=False)]


class _Header(NamedTuple):
    """What the C3D header (block 1) says about the 3D data."""

    points: int              # word 2
    frames: int | None       # words 4-5: last - first + 1; None when it cannot say (> 65535)
    rate: float              # words 11-12, a float in the processor's format
    data_start: int          # word 9: the first 512-byte block of the data section
    parameters: frozenset[str] = frozenset()   # every GROUP:NAME the parameter section has


def _header_float(raw: bytes, processor: int) -> float:
    """A 4-byte float of the header: IEEE little-endian (Intel), big-endian (MIPS) or DEC."""
    if processor == 86:
        return struct.unpack(">f", raw)[0]
    if processor == 85:                      # VAX F: words swapped, exponent bias 2 higher
        return struct.unpack("<f", raw[2:4] + raw[0:2])[0] / 4.0
    return struct.unpack("<f", raw)[0]


def _check_header(path: str | Path) -> _Header:
    """Check the file against its own header before ezc3d reads it; return the header.

    The header (block 1) says where the parameter section starts (byte 0: its first 512-byte
    block), the section's first 4 bytes its length in blocks (byte 2) and the processor type
    (byte 3: 84 Intel, 85 DEC, 86 MIPS big-endian), and header word 9 the block where the data
    starts. ezc3d reads past the end of a file cut before those points (it crashed or hung on
    such files), so a file shorter than they say is refused as truncated here. The counts come
    from the header words, because ezc3d rewrites its copy of them from the parameters (a
    truncated data section, or parameters that contradict the header, would pass unnoticed).
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
    words = np.frombuffer(head[:20], dtype=f"{order}u2")
    data_start = (int(words[8]) - 1) * 512
    if size < params_end:
        raise BadInput(path, f"truncated: {size} bytes end inside the parameter section "
                             f"(bytes {start} to {params_end})")
    if size < data_start:
        raise BadInput(path, f"truncated: {size} bytes end before the data section (byte "
                             f"{data_start})")
    with open(path, "rb") as f:
        f.seek(start)
        numbers, names = _check_parameters(path, f.read(params_end - start), param[3], start)
    _check_analog_scales(numbers, names, path)
    first, last = int(words[3]), int(words[4])
    frames = None if last >= 65535 or last < first else last - first + 1
    header = _Header(points=int(words[1]), frames=frames,
                     rate=_header_float(head[20:24], param[3]), data_start=int(words[8]),
                     parameters=frozenset(names))
    _check_against_header(numbers, header, path)
    return header


def _number(raw: bytes, kind: int, processor: int) -> float:
    """One parameter value: a byte, an unsigned int16 (counts above 32767 are written so) or
    a float in the processor's format."""
    if kind == 4:
        return _header_float(raw, processor)
    if kind == 2:
        return float(struct.unpack(">H" if processor == 86 else "<H", raw)[0])
    return float(raw[0])


def _count(params: dict, group: str, name: str, path: str | Path) -> int | None:
    """A count parameter (POINT:USED, POINT:FRAMES, ...) as an int; None when absent."""
    values = np.ravel(params.get(group, {}).get(name, {}).get("value", []))
    if values.size == 0:
        return None
    v = values[0]
    if not isinstance(v, int | float | np.number) or not float(v).is_integer() or v < 0:
        raise BadInput(path, f"C3D parameter {group}:{name} {v!r} is not a count")
    return int(v)


def _check_against_header(numbers: dict[str, float], header: _Header,
                          path: str | Path) -> None:
    """The POINT parameters must say what the header says.

    ezc3d sizes the data by POINT:USED and POINT:FRAMES (and rewrites the header from them), so
    a count that disagrees with the header would have it read the data block with another
    stride (every marker shifted) or past the frames the file holds. A header rate of 0 (left
    unset by some writers) is not compared.
    """
    def said(name: str) -> float | None:
        return numbers.get(f"POINT:{name}")

    checks = [("USED", "{} points", header.points), ("FRAMES", "{} frames", header.frames),
              ("DATA_START", "data block {}", header.data_start)]
    for name, what, value in checks:
        v = said(name)
        if v is not None and value is not None and v != value:
            raise BadInput(path, f"POINT:{name} says {what.format(f'{v:g}')} but the header "
                                 f"says {what.format(value)}")
    rate = said("RATE")
    if rate is not None and header.rate > 0 and not np.isclose(rate, header.rate, rtol=1e-4):
        raise BadInput(path, f"POINT:RATE says {rate:g} Hz but the header says "
                             f"{header.rate:g} Hz")
    scale = said("SCALE")
    if scale is not None and (scale == 0 or not np.isfinite(scale)):
        raise BadInput(path, f"POINT:SCALE {scale:g} is not a scale factor (a non-zero number)")


def _check_analog_scales(numbers: dict[str, float], names: set[str] | frozenset[str],
                         path: str | Path, required: tuple[str, ...] = ("SCALE", "OFFSET")
                         ) -> None:
    """A file with analog channels must say how to scale them: ezc3d (1.7) crashes on one
    without ANALOG:SCALE or ANALOG:OFFSET (so every reader checks those), and takes a missing
    ANALOG:GEN_SCALE as 1 (the analog reader refuses that too)."""
    used = numbers.get("ANALOG:USED")
    if not used:
        return
    for name in required:
        if f"ANALOG:{name}" not in names:
            raise BadInput(path, f"ANALOG:USED says {used:g} analog channels but the parameter "
                                 f"ANALOG:{name} is missing: the analog values cannot be scaled")


def _check_parameters(path: str | Path, section: bytes, processor: int,
                      offset: int) -> tuple[dict[str, float], set[str]]:
    """Walk the parameter records as ezc3d will, refusing any that would lead it astray; return
    the single-number parameters as ``{"GROUP:NAME": value}``, as the file has them, and the
    names (``GROUP:NAME``) of all parameters.

    A record: name length (int8, negative when locked; 0 ends the section), group id (int8),
    the name, the int16 offset from that field to the next record (0: the last), then a group's
    description or a parameter's type (int8: -1 char, 1 byte, 2 int16, 4 float), dimension
    count, dimensions (uint8 each), data and description. ezc3d trusts these numbers; a damaged
    one made it crash or loop, so each record must fit before the next, and the next must lie
    ahead, inside the section.
    """
    order = ">" if processor == 86 else "<"
    groups: dict[int, str] = {}
    numbers: dict[tuple[int, str], float] = {}
    present: set[tuple[int, str]] = set()

    def found() -> tuple[dict[str, float], set[str]]:
        return ({f"{groups.get(g, g)}:{name}": v for (g, name), v in numbers.items()},
                {f"{groups.get(g, g)}:{name}" for g, name in present})

    pos = 4
    while pos + 2 <= len(section):
        n = abs(struct.unpack_from("b", section, pos)[0])
        if n == 0:
            return found()
        gid = struct.unpack_from("b", section, pos + 1)[0]
        name = section[pos + 2:pos + 2 + n].decode("latin-1").upper()
        link = pos + 2 + n
        if link + 2 > len(section):
            break
        step = struct.unpack_from(order + "h", section, link)[0]
        end = link + 2
        if gid < 0:
            groups[-gid] = name
        elif end + 2 <= len(section):
            present.add((gid, name))
            kind, dims = struct.unpack_from("bB", section, end)
            shape = section[end + 2:end + 2 + dims]
            size = int(np.prod(list(shape))) if dims else 1
            value = section[end + 2 + dims:end + 2 + dims + abs(kind)]
            if size == 1 and kind in (1, 2, 4) and len(value) == kind:
                numbers[gid, name] = _number(value, kind, processor)
            end += 2 + dims + abs(kind) * size
        if end < len(section):
            end += 1 + section[end]                                   # the description
        nxt = link + step
        if step < 0 or end > len(section) or (step and nxt < end):
            raise BadInput(path, "damaged parameter section: a record does not fit where "
                                 "the next one starts", where=f"byte {offset + pos}")
        if step == 0:
            return found()
        pos = nxt
    raise BadInput(path, "damaged parameter section: records run past its end",
                   where=f"byte {offset + pos}")


def _open(path: str | Path) -> tuple[_Header, Any]:
    """The checked header and ezc3d's reading of the file."""
    import ezc3d

    if not Path(path).is_file():
        raise BadInput(path, "no such file")
    header = _check_header(path)
    try:
        c = ezc3d.c3d(str(path))
    except Exception as e:  # ezc3d raises bare RuntimeError/IndexError/... on bad files
        raise BadInput(path, f"not a readable C3D file ({e})") from None
    return header, c


def _rate(params: dict, group: str, path: str | Path) -> float:
    """POINT:RATE or ANALOG:RATE as a number."""
    rate = _first(params, group, "RATE", path)
    if not isinstance(rate, int | float | np.number):
        raise BadInput(path, f"{group}:RATE {rate!r} is not a number")
    return float(rate)


def read_c3d(path: str | Path) -> MarkerSeries:
    """Read the 3D points of a C3D file: metres, NaN where the residual is negative."""
    header, c = _open(path)
    params = c["parameters"]
    points = np.asarray(c["data"]["points"], dtype=np.float64)          # (4, N, T)
    residuals = np.asarray(c["data"]["meta_points"]["residuals"], dtype=np.float64)
    if points.ndim != 3 or points.shape[0] < 3:
        raise BadInput(path, f"C3D points have shape {points.shape}, expected (4, N, T)")
    n_points, n_frames = points.shape[1], points.shape[2]
    if header.frames is not None and header.frames != n_frames:
        raise BadInput(path, f"truncated: the header says {header.frames} frames but "
                             f"{n_frames} could be read", where=f"frame {n_frames}")
    rate = _rate(params, "POINT", path)
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


def read_c3d_analog(path: str | Path) -> AnalogExport:
    """Read the analog channels of a C3D file (ANALOG section) in the units it states.

    The C3D standard's physical value is ``(raw - ANALOG:OFFSET) * ANALOG:SCALE *
    ANALOG:GEN_SCALE``. ezc3d (1.7) already applies the scales, so they are checked and recorded
    here, never applied a second time; but it subtracts ``|OFFSET|``, which is wrong for a
    negative offset (a signed one, or with ``ANALOG:FORMAT`` UNSIGNED one above 32767 stored as
    int16), so the difference is added back (:func:`_offset_fix`). tests/test_analog.py checks
    all of it against the raw bytes of a real export. Missing or zero scales are bad input.
    """
    header, c = _open(path)
    params = c["parameters"]
    analog = params.get("ANALOG")
    values = np.asarray(c["data"]["analogs"], dtype=np.float64)         # (1, C, T)
    n = values.shape[1] if values.ndim == 3 else 0
    if analog is None or n == 0:
        raise BadInput(path, "the C3D file has no analog channels (no ANALOG section data)")
    used = _count(params, "ANALOG", "USED", path)
    if used is not None and used != n:
        raise BadInput(path, f"ANALOG:USED says {used} channels but the data hold {n}")
    scales, stored, gen = _analog_scales(params, header, n, path)
    unsigned = "UNSIGNED" in [str(v).strip().upper() for v in _texts(analog, "FORMAT", 1)]
    offsets = np.where(unsigned & (stored < 0), stored + 65536, stored)
    point_rate, rate = _rate(params, "POINT", path), _rate(params, "ANALOG", path)
    samples_per_frame(path, rate, point_rate)
    labels = _texts(analog, "LABELS", n)
    if not all(labels):
        raise BadInput(path, f"ANALOG:LABELS names {sum(map(bool, labels))} of {n} channels")
    return AnalogExport(
        source=str(path), format="c3d", labels=labels,
        descriptions=_texts(analog, "DESCRIPTIONS", n), units=_texts(analog, "UNITS", n),
        scales=scales, offsets=offsets, gen_scale=gen, rate_hz=rate,
        values=values[0].T + _offset_fix(stored, offsets) * scales * gen,
        point_rate_hz=point_rate, meta={"first_frame": int(c["header"]["points"]["first_frame"])})


def _analog_scales(params: dict, header: _Header, n: int,
                   path: str | Path) -> tuple[np.ndarray, np.ndarray, float]:
    """ANALOG:SCALE (n), ANALOG:OFFSET (n, as stored) and ANALOG:GEN_SCALE: each present (in
    the file, not filled in by ezc3d), the scales finite and non-zero."""
    _check_analog_scales({"ANALOG:USED": float(n)}, header.parameters, path,
                         ("SCALE", "OFFSET", "GEN_SCALE"))

    def numbers(name: str) -> np.ndarray:
        return np.ravel(np.asarray(_param(params, "ANALOG", name, path), dtype=np.float64))

    scales, offsets, gen = numbers("SCALE"), numbers("OFFSET"), numbers("GEN_SCALE")
    check_scales(path, "ANALOG:SCALE", scales, n)
    check_scales(path, "ANALOG:GEN_SCALE", gen[:1], 1)
    if offsets.size < n:
        raise BadInput(path, f"ANALOG:OFFSET has {offsets.size} values for {n} analog channels")
    return scales[:n], offsets[:n], float(gen[0])


def _offset_fix(stored: np.ndarray, true: np.ndarray) -> np.ndarray:
    """Per channel, the offset ezc3d 1.7 subtracted (``|stored|``) minus the standard's."""
    return np.abs(stored) - true


def _texts(group: dict, name: str, n: int) -> list[str]:
    """A text parameter of the ANALOG group, continued in NAME2, NAME3 ... (more than 255
    channels), as ``n`` stripped strings ("" where the file has fewer)."""
    out = [str(s).strip() for s in group.get(name, {}).get("value", [])]
    k = 2
    while f"{name}{k}" in group:
        out += [str(s).strip() for s in group[f"{name}{k}"]["value"]]
        k += 1
    return (out + [""] * n)[:n]

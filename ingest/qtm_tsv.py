"""QTM TSV exports: 3D marker trajectories and 6D rigid bodies, in every layout QTM has written.

The header is read key by key (``NO_OF_FRAMES``, ``FREQUENCY``, ``MARKER_NAMES`` / ``BODY_NAMES``,
``EVENT`` lines, ...), never as a fixed number of lines. After it may come a label line
(``Frame Time <name> X ...`` in newer exports, `` X Y Z Yaw ...`` once for all bodies in old 6D
exports), then the data block, which pyarrow's C++ CSV reader parses (fast, and strict: every row
must have the same number of fields). What the header claims is checked against the data before
it is trusted. Gaps (``NaN``, ``null``, empty cells, an exact ``0 0 0`` triple, a lost body with
residual -1) become NaN; millimetres become metres.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.csv as pcsv

from core.errors import BadInput
from core.series import BodySeries, MarkerSeries, frame_times_ns, time_to_ns
from core.units import length_scale
from ingest.analog import AnalogExport, check_scales
from ingest.qtm_header import (
    column_problem,
    count,
    event_problem,
    finite,
    header_problem,
    names_problem,
    rate_problem,
)
from ingest.sniff import check_last_line

_KEY = re.compile(r"[A-Z][A-Z0-9_]*")
_LIST_KEYS = ("MARKER_NAMES", "BODY_NAMES", "TRAJECTORY_TYPES")
_GAPS = ["", "NaN", "nan", "NAN", "-nan", "-NaN", "null", "NULL", "Null"]
_GAP_SET = frozenset(_GAPS)
_UNIT_KEYS = ("MARKER_UNITS", "POSITION_UNITS", "LENGTH_UNITS", "UNITS")
_FIRST_KEYS = ("NO_OF_FRAMES", "FILE_VERSION", "NO_OF_CAMERAS", "NO_OF_MARKERS", "NO_OF_BODIES",
               "FREQUENCY", "TOT_NO_OF_CHAN", "NO_OF_SAMPLES")
_ANALOG_LEAD = ("SAMPLE", "TIME")        # the analog export's leading columns
_MAX_LINE = 1 << 22          # a header line longer than this is not QTM's
_MAX_HEADER_LINES = 100_000
# one body in a 6D row: 16 values; where each sits when the file has no label line
_BODY_FIELDS = 16
_BODY_DEFAULT = {"X": 0, "Y": 1, "Z": 2, "Residual": 6, **{f"Rot[{k}]": 7 + k for k in range(9)}}


@dataclass
class _Head:
    """What the lines before the data block say, and where the data block starts."""

    path: Path
    keys: dict[str, list[str]] = field(default_factory=dict)
    key_lines: dict[str, int] = field(default_factory=dict)
    events: list[tuple[str, int, float]] = field(default_factory=list)
    event_lines: list[int] = field(default_factory=list)
    labels: list[str] | None = None      # the label / column line, trailing empties removed
    labels_line: int = 0                 # its 1-based line number
    first: list[str] | None = None       # fields of the first data row (None: no data)
    first_line: int = 0                  # 1-based line number of the first data row
    offset: int = 0                      # byte offset of the first data row

    def bad(self, what: str, line: int | None = None) -> BadInput:
        return BadInput(self.path, what, where=None if line is None else f"line {line}")

    def scalar(self, key: str) -> str | None:
        v = self.keys.get(key)
        return v[0].strip() if v else None

    def number(self, key: str) -> float | None:
        """A numeric header value; None when absent (or, before :func:`_check_header` has run,
        not a number)."""
        v = self.scalar(key)
        try:
            return None if v is None else float(v)
        except ValueError:
            return None


def looks_like_qtm_tsv(text: str) -> bool:
    """Whether a file's first characters start like a QTM TSV export (a header key line)."""
    first = text.lstrip("\ufeff").split("\n", 1)[0].split("\t", 1)[0].strip()
    return first in _FIRST_KEYS


def parse_qtm_header(path: str | Path) -> dict[str, Any]:
    """The header of a QTM TSV export as ``{key: value}``.

    Values are strings, except: ``MARKER_NAMES``, ``BODY_NAMES`` and ``TRAJECTORY_TYPES`` are
    lists of names; keys with several values (``TIME_STAMP  date  ticks``) are lists of strings;
    ``EVENT`` is a list of ``(label, frame, time_s)``.
    """
    head = _scan(path)
    out: dict[str, Any] = {}
    for key, values in head.keys.items():
        if key in _LIST_KEYS:
            out[key] = [v.strip() for v in values]
        else:
            out[key] = values[0] if len(values) == 1 else list(values)
    if head.events:
        out["EVENT"] = list(head.events)
    return out


def read_qtm_tsv(path: str | Path) -> MarkerSeries | BodySeries:
    """Read a QTM TSV export: 3D (``MARKER_NAMES``) or 6D (``BODY_NAMES``), found by its keys."""
    head = _scan(path)
    if "MARKER_NAMES" in head.keys and "BODY_NAMES" in head.keys:
        raise head.bad("header has both MARKER_NAMES and BODY_NAMES")
    if "MARKER_NAMES" in head.keys:
        return _read_3d(head)
    if "BODY_NAMES" in head.keys:
        return _read_6d(head)
    kind = head.scalar("DATA_INCLUDED") or "unknown"
    raise head.bad(f"unsupported QTM TSV export (DATA_INCLUDED {kind}; no MARKER_NAMES or "
                   "BODY_NAMES)")


def read_qtm_3d(path: str | Path) -> MarkerSeries:
    """Read a QTM TSV 3D export: marker positions in metres, NaN where missing."""
    head = _scan(path)
    if "MARKER_NAMES" not in head.keys:
        raise head.bad("not a QTM 3D export: no MARKER_NAMES in the header")
    return _read_3d(head)


def read_qtm_6d(path: str | Path) -> BodySeries:
    """Read a QTM TSV 6D export: body positions (m), rotation matrices, residuals (m)."""
    head = _scan(path)
    if "BODY_NAMES" not in head.keys:
        raise head.bad("not a QTM 6D export: no BODY_NAMES in the header")
    return _read_6d(head)


# ---------------------------------------------------------------------------- header


def _decode(raw: bytes) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("cp1252", errors="replace")


def _is_value(token: str) -> bool:
    """A number or a gap marker, i.e. something a data cell may hold."""
    t = token.strip()
    if t in _GAP_SET:
        return True
    try:
        float(t)
    except ValueError:
        return False
    return True


def _scan(path: str | Path) -> _Head:
    """Read the header keys, the optional label line and the first data row."""
    head = _Head(Path(path))
    try:
        f = open(path, "rb")
    except FileNotFoundError:
        raise BadInput(path, "no such file") from None
    except OSError as e:
        raise BadInput(path, f"cannot read ({e.strerror or e})") from None
    with f:
        line_no = 0
        while True:
            raw = f.readline(_MAX_LINE)
            line_no += 1
            if not raw:
                break
            if len(raw) == _MAX_LINE or line_no > _MAX_HEADER_LINES or b"\x00" in raw:
                raise head.bad("not a QTM TSV export (binary or overlong lines)", line_no)
            text = _decode(raw).rstrip("\r\n")
            if line_no == 1:
                text = text.lstrip("\ufeff")
            fields = text.split("\t")
            if not text.strip():
                continue
            key = fields[0].strip()
            if head.labels is None and _is_key(key):
                _header_line(head, key, fields[1:], line_no)
                continue
            if not head.keys:
                raise head.bad("not a QTM TSV export: no header keys such as NO_OF_FRAMES", 1)
            if head.labels is None and not all(_is_value(x) for x in fields):
                head.labels = _strip_trailing(fields)
                head.labels_line = line_no
                continue
            head.first, head.first_line = fields, line_no
            head.offset = f.tell() - len(raw)
            break
    if not head.keys:
        raise head.bad("not a QTM TSV export: no header keys such as NO_OF_FRAMES", 1)
    return head


def _is_key(token: str) -> bool:
    """Header keys are upper-case words (``NO_OF_FRAMES``, ``EVENT``); a lone ``X`` is a label."""
    return len(token) > 1 and bool(_KEY.fullmatch(token)) and not _is_value(token)


def _header_line(head: _Head, key: str, values: list[str], line_no: int) -> None:
    if key == "EVENT":
        try:
            label, frame, time = values[0].strip(), count(values[1]), float(values[2])
        except (IndexError, ValueError):
            frame = None
        if frame is None:
            raise head.bad("EVENT line must be: EVENT <label> <frame number> <time in s>",
                           line_no)
        head.events.append((label, frame, time))
        head.event_lines.append(line_no)
        return
    if key in head.keys:
        raise head.bad(f"header key {key} appears twice", line_no)
    head.keys[key] = _strip_trailing(values)
    head.key_lines[key] = line_no


def _strip_trailing(fields: list[str]) -> list[str]:
    end = len(fields)
    while end and not fields[end - 1].strip():
        end -= 1
    return fields[:end]


def _check_header(head: _Head, names_key: str, count_key: str) -> list[str]:
    """Refuse a header that cannot be right (:mod:`ingest.qtm_header`); return the names."""
    for problem in (header_problem(head.keys, names_key),
                    names_problem(head.keys, names_key, count_key)):
        if problem is not None:
            key, what = problem
            raise head.bad(what, _key_line(head, key))
    return [n.strip() for n in head.keys[names_key]]


def _key_line(head: _Head, key: str) -> int:
    """1-based line of a header key."""
    return head.key_lines.get(key, 1)


def _length_scale(head: _Head) -> tuple[float, str]:
    """Metres per file unit; QTM writes mm, a ``MARKER_UNITS``-like key may say otherwise."""
    for key in _UNIT_KEYS:
        values = head.keys.get(key)
        if values:
            unit = values[0].strip()
            try:
                return length_scale(unit), unit
            except ValueError as e:
                raise head.bad(f"{key} {e}", _key_line(head, key)) from None
    return 1e-3, "mm"


# ---------------------------------------------------------------------------- data block


def _parse_block(
    head: _Head, n_fields: int, time_col: int | None, value_cols: list[int],
    block: Callable[[np.ndarray], None] | None = None,
) -> tuple[np.ndarray | None, np.ndarray]:
    """Parse the data block (rows of ``n_fields`` fields) into float64 arrays.

    Returns the Time column (or None) and ``values[row, i]`` = column ``value_cols[i]``, C-order.
    pyarrow parses the block batch by batch and turns each batch into a row-major array in C++;
    ``block`` post-processes each batch's rows in place while they are still in cache. Only one
    parsed batch is alive at a time, so memory stays near the size of the result.
    """
    _require_data(head)
    wanted = ([] if time_col is None else [time_col]) + value_cols
    names = [f"c{i}" for i in range(n_fields)]
    cols = [names[i] for i in wanted]
    shift = len(wanted) - len(value_cols)
    values = np.empty((_capacity(head, n_fields), len(value_cols)))
    times = None if time_col is None else np.empty(len(values))
    n = 0
    try:
        with pa.OSFile(str(head.path)) as f:
            f.seek(head.offset)
            reader = pcsv.open_csv(
                f,
                read_options=pcsv.ReadOptions(column_names=names, block_size=1 << 22),
                parse_options=pcsv.ParseOptions(delimiter="\t", quote_char=False),
                convert_options=pcsv.ConvertOptions(
                    include_columns=cols, column_types=dict.fromkeys(cols, pa.float64()),
                    null_values=_GAPS, strings_can_be_null=True,
                ),
            )
            for batch in reader:
                rows = np.asarray(batch.to_tensor(null_to_nan=True, row_major=True))
                if np.isinf(rows).any():                  # QTM writes gaps as NaN, never inf
                    r, j = np.argwhere(np.isinf(rows))[0]
                    raise head.bad(f"{rows[r, j]} in column {wanted[j] + 1} is not a finite "
                                   "number", head.first_line + n + int(r))
                if n + len(rows) > len(values):
                    values, times = _grow(head, values, times, n + len(rows))
                dst = values[n:n + len(rows)]
                dst[:] = rows[:, shift:]
                if times is not None:
                    times[n:n + len(rows)] = rows[:, 0]
                if block is not None:
                    block(dst)
                n += len(rows)
    except (pa.ArrowInvalid, pa.ArrowTypeError) as e:
        raise _diagnose(head, n_fields, wanted, str(e)) from None
    except OSError as e:
        raise head.bad(f"cannot read ({e})") from None
    _check_rows(head, n, n_fields)
    if n < len(values):                          # over-allocated (no NO_OF_FRAMES): trim
        values = values[:n].copy()
        times = None if times is None else times[:n].copy()
    return times, values


def _capacity(head: _Head, n_fields: int) -> int:
    """Rows to allocate: NO_OF_FRAMES, but never more than the bytes left could hold (a row
    takes at least ``n_fields`` bytes), so a lying header cannot make us allocate."""
    left = head.path.stat().st_size - head.offset
    bound = left // max(n_fields, 1) + 1
    claimed = head.number("NO_OF_FRAMES")
    if claimed is None or not (0 < claimed < bound):
        return min(bound, 65536)
    return int(claimed)


def _grow(head: _Head, values: np.ndarray, times: np.ndarray | None,
          need: int) -> tuple[np.ndarray, np.ndarray | None]:
    """More rows than allocated: an error if NO_OF_FRAMES said fewer, else double."""
    claimed = head.number("NO_OF_FRAMES")
    if claimed is not None and need > claimed:
        raise head.bad(f"NO_OF_FRAMES says {claimed:.0f} but the file has more data rows",
                       head.first_line + int(claimed))
    size = max(need, 2 * len(values))
    bigger = np.empty((size, values.shape[1]))
    bigger[:len(values)] = values
    if times is not None:
        t = np.empty(size)
        t[:len(times)] = times
        times = t
    return bigger, times


def _require_data(head: _Head) -> None:
    if head.first is None:
        frames = head.scalar("NO_OF_FRAMES")
        raise head.bad(f"truncated: no data rows (NO_OF_FRAMES says {frames})"
                       if frames not in (None, "0") else "no data rows")


def _diagnose(head: _Head, n_fields: int, wanted: list[int], err: str) -> BadInput:
    """Find the first bad line of the data block (slow; runs only after a parse error)."""
    with open(head.path, "rb") as f:
        f.seek(head.offset)
        line_no = head.first_line - 1
        for raw in f:
            line_no += 1
            text = _decode(raw).rstrip("\r\n")
            if not text.strip():
                continue
            fields = text.split("\t")
            if len(fields) != n_fields:
                end = "" if raw.endswith(b"\n") else " (the file ends here: truncated)"
                return head.bad(f"row has {len(fields)} fields, expected {n_fields}{end}",
                                line_no)
            for i in wanted:
                if not _is_value(fields[i]):
                    return head.bad(f"{fields[i].strip()!r} in column {i + 1} is not a number",
                                    line_no)
    return head.bad(f"cannot parse the data block ({err})")


def _check_rows(head: _Head, n_rows: int, n_fields: int) -> None:
    """The row count must match NO_OF_FRAMES and the last row must be complete."""
    last = head.first_line + n_rows - 1
    check_last_line(head.path, "\t", n_fields, head.first or [], last)
    claimed = head.scalar("NO_OF_FRAMES")
    frames = None if claimed is None else count(claimed)
    if frames is None:                           # absent (checked by _check_header)
        return
    if n_rows < frames:
        raise head.bad(f"truncated: NO_OF_FRAMES says {frames} but the file has {n_rows} data "
                       "rows", last)
    if n_rows > frames:
        raise head.bad(f"NO_OF_FRAMES says {frames} but the file has {n_rows} data rows",
                       head.first_line + frames)


def _time_ns(head: _Head, t: np.ndarray | None, n: int) -> tuple[np.ndarray, float]:
    """Time stamps (ns) from the Time column, else frame index / FREQUENCY; and the rate."""
    freq = head.number("FREQUENCY")
    line = f"line {_key_line(head, 'FREQUENCY')}"
    if t is None:
        if freq is None:
            raise head.bad("no Time column and no numeric FREQUENCY: cannot time the frames")
        return frame_times_ns(n, freq, head.path, "FREQUENCY", line), freq
    if freq is not None and not (np.isfinite(freq) and freq > 0):
        raise head.bad(f"FREQUENCY {freq:g} is not a positive rate", _key_line(head, "FREQUENCY"))
    bad = np.flatnonzero(np.isnan(t))
    if bad.size:
        raise head.bad("Time is missing", head.first_line + int(bad[0]))
    ns = time_to_ns(t, head.path, where=lambda i: f"line {head.first_line + i}")
    steps = np.diff(ns)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise head.bad(f"Time is not increasing ({t[i]:g} s after {t[i - 1]:g} s, frame {i})",
                       head.first_line + i)
    if freq is None:
        return ns, 1e9 / float(np.median(steps)) if steps.size else float("nan")
    off = rate_problem(freq, n, (ns[-1] - ns[0]) / 1e9)
    if off is not None:
        raise head.bad(off, _key_line(head, "FREQUENCY"))
    return ns, freq


def _events(head: _Head, rate: float) -> list[tuple[str, int]]:
    """The EVENT lines as (label, time in ns); each one's frame and time must agree at
    ``rate`` (the file's frame rate, once the data have confirmed it)."""
    for (label, frame, time), line in zip(head.events, head.event_lines, strict=True):
        what = event_problem(label, frame, time, rate)
        if what is not None:
            raise head.bad(what, line)
    ns = time_to_ns([t for _, _, t in head.events], head.path, where=lambda i: f"EVENT {i + 1}")
    return [(label, int(t)) for (label, _, _), t in zip(head.events, ns, strict=True)]


def _meta(head: _Head, fmt: str, unit: str) -> dict[str, Any]:
    header = {k: (v[0] if len(v) == 1 else list(v)) for k, v in head.keys.items()
              if k not in _LIST_KEYS}
    return {"format": fmt, "units_in_file": unit, "header": header}


# ---------------------------------------------------------------------------- 3D


def _layout_3d(head: _Head, names: list[str]) -> tuple[int, int | None, np.ndarray]:
    """Fields per row, the Time column (or None) and the (M, 3) columns of X, Y, Z."""
    assert head.first is not None
    n_fields, m = len(head.first), len(names)
    if head.labels is not None:
        labels = [s.strip() for s in head.labels]
        if not (n_fields == len(labels) or (n_fields == len(labels) + 1
                                            and not head.first[-1].strip())):
            raise head.bad(f"row has {n_fields} fields but the column line names "
                           f"{len(labels)}", head.first_line)
        index: dict[str, int] = {}
        for i, label in enumerate(labels):
            index.setdefault(label, i)
        if "Frame" not in index and not any(f"{n} X" in index for n in names):
            token = next(x for x in labels if not _is_value(x))
            raise head.bad(f"{token!r} is not a number (and this is no column line)",
                           head.labels_line)
        problem = column_problem(labels, names)
        if problem is not None:
            col, what = problem
            raise head.bad(f"{what} (column {col + 1})", head.labels_line)
        cols = np.empty((m, 3), dtype=np.int64)
        for j, name in enumerate(names):
            for k, axis in enumerate("XYZ"):
                col = index.get(f"{name} {axis}")
                if col is None:
                    raise head.bad(f"column line has no column '{name} {axis}' for marker "
                                   f"{name!r} of MARKER_NAMES", head.labels_line)
                cols[j, k] = col
        return n_fields, index.get("Time"), cols
    core = n_fields
    if not head.first[-1].strip() and n_fields in (3 * m + 1, 3 * m + 3):
        core -= 1                                   # a trailing tab
    if core == 3 * m:
        lead, time_col = 0, None
    elif core == 3 * m + 2 and count(head.first[0]) is not None \
            and finite(head.first[1]) is not None:
        lead, time_col = 2, 1                       # Frame, Time
    else:
        why = (f", but {head.first[0].strip()!r} {head.first[1].strip()!r} are no frame number "
               "and time" if core == 3 * m + 2 else "")
        raise head.bad(f"row has {n_fields} fields; {m} markers need {3 * m} "
                       f"(or {3 * m + 2} with Frame and Time){why}", head.first_line)
    return n_fields, time_col, lead + np.arange(3 * m).reshape(m, 3)


def _read_3d(head: _Head) -> MarkerSeries:
    names = _check_header(head, "MARKER_NAMES", "NO_OF_MARKERS")
    types = head.keys.get("TRAJECTORY_TYPES")
    scale, unit = _length_scale(head)
    _require_data(head)
    n_fields, time_col, cols = _layout_3d(head, names)

    def to_metres(block: np.ndarray) -> None:
        xyz = block.reshape(len(block), len(names), 3)
        xyz *= scale
        x, y, z = xyz[..., 0], xyz[..., 1], xyz[..., 2]
        missing = np.isnan(x + y + z) | ((x == 0) & (y == 0) & (z == 0))   # NaN, or 0 0 0
        xyz[missing] = np.nan

    t, values = _parse_block(head, n_fields, time_col, [int(c) for c in cols.ravel()],
                             to_metres)
    n = len(values)
    time_ns, rate = _time_ns(head, t, n)
    positions = values.reshape(n, len(names), 3)
    meta = _meta(head, "qtm_tsv_3d", unit)
    if types is not None:
        meta["trajectory_types"] = [t.strip() for t in types]
    return MarkerSeries(source=str(head.path), time_ns=time_ns, labels=names,
                        positions=positions, rate_hz=float(rate), events=_events(head, rate),
                        meta=meta)


# ---------------------------------------------------------------------------- 6D


def _body_offsets(head: _Head, labels: list[str]) -> dict[str, int]:
    """Where X, Y, Z, Residual and Rot[0..8] sit inside one body's 16 fields."""
    group = [s.strip() for s in labels[:_BODY_FIELDS]]
    offsets = {}
    for token in _BODY_DEFAULT:
        hit = [i for i, s in enumerate(group) if s == token or s.endswith(" " + token)]
        if not hit:
            raise head.bad(f"label line has no '{token}' column for the first body",
                           head.labels_line)
        offsets[token] = hit[0]
    return offsets


def _check_body_labels(head: _Head, names: list[str], lead: int, stride: int) -> None:
    """The label line must describe the bodies of BODY_NAMES, in order, one group of 16 labels
    each laid out as the first (``<body> X  Y  Z  Roll ... Rot[8]``, the body's name on any of
    them), or, in old exports, one unnamed group for all bodies. A column line (``Frame Time
    ...``) must be as wide as the rows."""
    assert head.first is not None
    labels = [s.strip() for s in head.labels or []]
    n_fields = len(head.first)
    shared = labels[0] != "Frame" and len(labels) <= lead + _BODY_FIELDS and len(names) > 1
    if not shared and not (n_fields == len(labels) or (
            n_fields == len(labels) + 1 and not head.first[-1].strip())):
        raise head.bad(f"row has {n_fields} fields but the column line names {len(labels)}",
                       head.first_line)
    groups = [labels[lead + stride * b:lead + stride * b + _BODY_FIELDS]
              for b in range(1 if shared else len(names))]   # old exports: one for all
    layout = [label.rpartition(" ")[2] for label in groups[0]]
    for b, group in enumerate(groups):
        for k, label in enumerate(group):
            body, _, word = label.rpartition(" ")
            col = lead + stride * b + k + 1
            if body and (shared or body != names[b]):
                want = f"body {b + 1} is {names[b]!r}" if not shared else \
                    f"this one label group serves all {len(names)} bodies"
                raise head.bad(f"column line names body {body!r} in column {col} ({label!r}), "
                               f"but in BODY_NAMES {want}", head.labels_line)
            if word != layout[k]:
                raise head.bad(f"column line has {label!r} in column {col} where body "
                               f"{names[b]!r} needs its {layout[k]!r} column, as the first "
                               "body has it", head.labels_line)
        sep = lead + stride * b + _BODY_FIELDS
        if stride > _BODY_FIELDS and sep < len(labels) and labels[sep]:
            raise head.bad(f"column line has {labels[sep]!r} in column {sep + 1}, which "
                           "separates two bodies", head.labels_line)


def _layout_6d(head: _Head, names: list[str]) -> tuple[int, int | None, int, int,
                                                     dict[str, int]]:
    """Fields per row, Time column, first body column, body stride (16 or 17), offsets."""
    assert head.first is not None
    first, n_fields, bodies = head.first, len(head.first), len(names)
    offsets = dict(_BODY_DEFAULT)
    if head.labels is not None and head.labels[0].strip() == "Frame":
        labels = [s.strip() for s in head.labels]
        time_col = labels.index("Time") if "Time" in labels else None
        leads = [1 if time_col is None else time_col + 1]
    elif head.labels is not None:
        time_col, leads = None, [0]
    else:
        time_col, leads = None, [0, 2]
    for lead in leads:
        if head.labels is not None:
            offsets = _body_offsets(head, head.labels[lead:])
        for stride in (_BODY_FIELDS, _BODY_FIELDS + 1):
            need = lead + stride * bodies - (stride - _BODY_FIELDS)
            if not (n_fields == need or (n_fields == need + 1 and not first[-1].strip())):
                continue                           # (need + 1: a trailing tab)
            seps = [] if stride == _BODY_FIELDS else [
                lead + stride * b + _BODY_FIELDS for b in range(bodies)
                if lead + stride * b + _BODY_FIELDS < n_fields]
            if any(first[i].strip() for i in seps):
                continue                           # separators must be empty
            if lead == 2 and head.labels is None:
                if not first[0].strip().isdigit():
                    continue
                time_col = 1
            if head.labels is not None:
                _check_body_labels(head, names, lead, stride)
            return n_fields, time_col, lead, stride, offsets
    raise head.bad(f"row has {n_fields} fields, which does not fit {bodies} bodies of "
                   f"{_BODY_FIELDS} values", head.first_line)


def _read_6d(head: _Head) -> BodySeries:
    names = _check_header(head, "BODY_NAMES", "NO_OF_BODIES")
    scale, unit = _length_scale(head)
    _require_data(head)
    n_fields, time_col, lead, stride, off = _layout_6d(head, names)
    tokens = ["X", "Y", "Z", "Residual", *(f"Rot[{k}]" for k in range(9))]
    cols = np.array([[lead + stride * b + off[t] for t in tokens] for b in range(len(names))])
    t, flat = _parse_block(head, n_fields, time_col, [int(c) for c in cols.ravel()])
    n = len(flat)
    time_ns, rate = _time_ns(head, t, n)
    values = flat.reshape(n, len(names), len(tokens))
    positions = values[..., 0:3] * scale
    residuals = values[..., 3] * scale
    rotations = values[..., 4:13].reshape(n, len(names), 3, 3).swapaxes(-1, -2).copy()
    lost = (np.isnan(values).any(axis=2) | (values[..., 3] < 0)
            | (np.abs(values[..., 4:13]).sum(axis=2) == 0))
    positions[lost] = np.nan
    residuals[lost] = np.nan
    rotations[lost] = np.nan
    return BodySeries(source=str(head.path), time_ns=time_ns, bodies=names,
                      positions=positions, rotations=rotations, residuals=residuals,
                      rate_hz=float(rate), events=_events(head, rate),
                      meta=_meta(head, "qtm_tsv_6d", unit))


# ---------------------------------------------------------------------------- analog


def read_qtm_analog(path: str | Path) -> AnalogExport:
    """Read a QTM analog TSV export (``<trial>_a.tsv``): one analog board's channels.

    Header keys (QTM's manual): ``TOT_NO_OF_CHAN``, ``NO_OF_SAMPLES`` (older exports),
    ``FREQUENCY`` or per-channel ``CHANNEL_FREQUENCIES`` and ``CHANNEL_SAMPLE_COUNTS``,
    ``CHANNEL_NAMES``, ``CHANNEL_GAIN`` (QTM writes 1), optionally ``CHANNEL_UNITS`` (else volts);
    then an optional ``SAMPLE TIME <names>`` column line and the samples. The first sample is at
    the first 3D frame of the same capture.
    """
    head = _scan(path)
    if "CHANNEL_NAMES" not in head.keys:
        raise head.bad("not a QTM analog export: no CHANNEL_NAMES in the header")
    names = [n.strip() for n in head.keys["CHANNEL_NAMES"]]
    n = len(names)
    problem = _analog_header_problem(head, names)
    if problem is not None:
        key, what = problem
        raise head.bad(what, _key_line(head, key))
    rate = _analog_rate(head, n)
    gains = _analog_list(head, "CHANNEL_GAIN", n, 1.0)
    try:
        check_scales(path, "CHANNEL_GAIN", gains, n)
    except BadInput as e:
        raise head.bad(e.what, _key_line(head, "CHANNEL_GAIN")) from None
    if np.any(gains != 1.0):
        raise head.bad("CHANNEL_GAIN other than 1: QTM writes its analog values with gain 1, "
                       "a file with other gains is not understood", _key_line(head, "CHANNEL_GAIN"))
    units = [u.strip() for u in head.keys.get("CHANNEL_UNITS", ["V"] * n)]
    if len(units) != n:
        raise head.bad(f"CHANNEL_UNITS has {len(units)} entries for {n} channels",
                       _key_line(head, "CHANNEL_UNITS"))
    _require_data(head)
    n_fields, time_col, cols = _layout_analog(head, names)
    t, values = _parse_block(head, n_fields, time_col, cols)
    _check_samples(head, values, rate, t)
    return AnalogExport(source=str(path), format="qtm_tsv_analog", labels=names,
                        descriptions=[""] * n, units=units, scales=gains, offsets=np.zeros(n),
                        gen_scale=1.0, rate_hz=rate, values=values,
                        meta={**_meta(head, "qtm_tsv_analog", units[0] if units else "V"),
                              "units_stated": "CHANNEL_UNITS" in head.keys})


def _analog_header_problem(head: _Head, names: list[str]) -> tuple[str, str] | None:
    """CHANNEL_NAMES: none empty, none twice, as many as TOT_NO_OF_CHAN says."""
    if not names or not all(names):
        return "CHANNEL_NAMES", "CHANNEL_NAMES has an empty name" if names else \
            "CHANNEL_NAMES lists no channels"
    dups = sorted({x for x in names if names.count(x) > 1})
    if dups:
        return "CHANNEL_NAMES", f"duplicate name(s) in CHANNEL_NAMES: {', '.join(dups)}"
    said = head.scalar("TOT_NO_OF_CHAN")
    if said is not None and count(said) != len(names):
        return "TOT_NO_OF_CHAN", (f"TOT_NO_OF_CHAN is {said} but CHANNEL_NAMES lists "
                                  f"{len(names)} names")
    return None


def _analog_list(head: _Head, key: str, n: int, default: float) -> np.ndarray:
    """A per-channel numeric header list (CHANNEL_GAIN, CHANNEL_FREQUENCIES, ...)."""
    values = head.keys.get(key)
    if values is None:
        return np.full(n, default)
    numbers = [finite(v) for v in values]
    if len(numbers) != n or any(v is None for v in numbers):
        raise head.bad(f"{key} must hold {n} numbers, one per channel", _key_line(head, key))
    return np.array(numbers, dtype=np.float64)


def _analog_rate(head: _Head, n: int) -> float:
    """The sample rate: CHANNEL_FREQUENCIES (all alike) or FREQUENCY."""
    if "CHANNEL_FREQUENCIES" in head.keys:
        rates = _analog_list(head, "CHANNEL_FREQUENCIES", n, 0.0)
        if np.any(rates != rates[0]):
            raise head.bad("CHANNEL_FREQUENCIES differ between channels; the force channels "
                           "must share one rate", _key_line(head, "CHANNEL_FREQUENCIES"))
        rate: float | None = float(rates[0])
    else:
        rate = head.number("FREQUENCY")
    if rate is None or not (np.isfinite(rate) and rate > 0):
        raise head.bad("no analog rate: FREQUENCY or CHANNEL_FREQUENCIES must be a number > 0")
    return float(rate)


def _layout_analog(head: _Head, names: list[str]) -> tuple[int, int | None, list[int]]:
    """Fields per row, the TIME column (or None) and each channel's column."""
    assert head.first is not None
    n_fields = len(head.first)
    if head.labels is not None:
        labels = [x.strip() for x in head.labels]
        lead = [x.upper() for x in labels[:2]]
        k = next((i for i in (2, 1, 0) if lead[:i] == list(_ANALOG_LEAD[:i])), 0)
        if labels[k:] != names:
            raise head.bad("column line does not name the channels of CHANNEL_NAMES in their "
                           "order", head.labels_line)
        time_col = 1 if k == 2 else None
    else:
        core = n_fields - (1 if not head.first[-1].strip() else 0)      # a trailing tab
        k = core - len(names)
        if k not in (0, 2):
            raise head.bad(f"row has {n_fields} fields; {len(names)} channels need "
                           f"{len(names)} (or {len(names) + 2} with SAMPLE and TIME)",
                           head.first_line)
        time_col = 1 if k == 2 else None
    return n_fields, time_col, list(range(k, k + len(names)))


def _check_samples(head: _Head, values: np.ndarray, rate: float, t: np.ndarray | None) -> None:
    """NO_OF_SAMPLES / CHANNEL_SAMPLE_COUNTS against the rows; the TIME column against the
    rate; no channel may miss a sample (force with holes is refused, as from a force log)."""
    n = len(values)
    counts = [count(v) for v in head.keys.get("CHANNEL_SAMPLE_COUNTS", [])]
    said = head.scalar("NO_OF_SAMPLES")
    for key, value in [("NO_OF_SAMPLES", None if said is None else count(said))] + \
            [("CHANNEL_SAMPLE_COUNTS", c) for c in counts]:
        if (key == "CHANNEL_SAMPLE_COUNTS" or said is not None) and value != n:
            raise head.bad(f"{key} says {head.keys[key][0].strip() if value is None else value}"
                           f" samples but the file has {n} rows", _key_line(head, key))
    bad = np.argwhere(np.isnan(values))
    if bad.size:
        row, col = bad[0]
        raise head.bad(f"analog channel {col + 1} has no value", head.first_line + int(row))
    if t is not None:
        off = rate_problem(rate, n, float(t[-1] - t[0]))
        if off is not None:
            raise head.bad(off.replace("FREQUENCY", "the analog rate").replace(
                "Time column", "TIME column").replace("frames", "samples"), head.first_line)

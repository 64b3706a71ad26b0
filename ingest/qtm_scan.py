"""The header of a QTM TSV export (3D, 6D or analog), read key by key, never as a fixed number
of lines, and what it says about the file.

Header lines are ``KEY<tab>value...`` (``NO_OF_FRAMES``, ``FREQUENCY``, ``MARKER_NAMES`` /
``BODY_NAMES``, ``EVENT`` lines, ...). After them may come a label line (``Frame Time <name> X
...`` in newer exports, `` X Y Z Yaw ...`` once for all bodies in old 6D exports), then the data
block, whose first row and byte offset the scan keeps for :mod:`ingest.qtm_block`. Whether each
value can be right is :mod:`ingest.qtm_header`'s to judge; :func:`check_header` refuses the
file, with its line, when one cannot.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from core.errors import BadInput
from core.units import length_scale
from ingest.qtm_header import count, header_problem, names_problem

GAPS = ["", "NaN", "nan", "NAN", "-nan", "-NaN", "null", "NULL", "Null"]   # a cell with no value
_GAP_SET = frozenset(GAPS)
_KEY = re.compile(r"[A-Z][A-Z0-9_]*")
_LIST_KEYS = ("MARKER_NAMES", "BODY_NAMES", "TRAJECTORY_TYPES")
_UNIT_KEYS = ("MARKER_UNITS", "POSITION_UNITS", "LENGTH_UNITS", "UNITS")
_FIRST_KEYS = ("NO_OF_FRAMES", "FILE_VERSION", "NO_OF_CAMERAS", "NO_OF_MARKERS", "NO_OF_BODIES",
               "FREQUENCY", "TOT_NO_OF_CHAN", "NO_OF_SAMPLES")
_MAX_LINE = 1 << 22          # a header line longer than this is not QTM's
_MAX_HEADER_LINES = 100_000


@dataclass
class QtmHead:
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
        """A numeric header value; None when absent (or, before :func:`check_header` has run,
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
    head = scan(path)
    out: dict[str, Any] = {}
    for key, values in head.keys.items():
        if key in _LIST_KEYS:
            out[key] = [v.strip() for v in values]
        else:
            out[key] = values[0] if len(values) == 1 else list(values)
    if head.events:
        out["EVENT"] = list(head.events)
    return out


def decode(raw: bytes) -> str:
    """A line's bytes as text: UTF-8, else (older QTM versions) Windows-1252."""
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("cp1252", errors="replace")


def is_value(token: str) -> bool:
    """A number or a gap marker, i.e. something a data cell may hold."""
    t = token.strip()
    if t in _GAP_SET:
        return True
    try:
        float(t)
    except ValueError:
        return False
    return True


def scan_export(path: str | Path, key: str, kind: str) -> QtmHead:
    """:func:`scan` a file that must be a QTM ``kind`` export: its header lists ``key``."""
    head = scan(path)
    if key not in head.keys:
        raise head.bad(f"not a QTM {kind} export: no {key} in the header")
    return head


def scan(path: str | Path) -> QtmHead:
    """Read the header keys, the optional label line and the first data row."""
    head = QtmHead(Path(path))
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
            text = decode(raw).rstrip("\r\n")
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
            if head.labels is None and not all(is_value(x) for x in fields):
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
    return len(token) > 1 and bool(_KEY.fullmatch(token)) and not is_value(token)


def _header_line(head: QtmHead, key: str, values: list[str], line_no: int) -> None:
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


def check_header(head: QtmHead, names_key: str, count_key: str) -> list[str]:
    """Refuse a header that cannot be right (:mod:`ingest.qtm_header`); return the names."""
    for problem in (header_problem(head.keys, names_key),
                    names_problem(head.keys, names_key, count_key)):
        if problem is not None:
            key, what = problem
            raise head.bad(what, key_line(head, key))
    return [n.strip() for n in head.keys[names_key]]


def check_row_width(head: QtmHead, labels: list[str]) -> None:
    """A column line must name every field of the first row (a trailing tab adds an empty one)."""
    assert head.first is not None
    n_fields = len(head.first)
    if not (n_fields == len(labels) or (n_fields == len(labels) + 1
                                        and not head.first[-1].strip())):
        raise head.bad(f"row has {n_fields} fields but the column line names {len(labels)}",
                       head.first_line)


def key_line(head: QtmHead, key: str) -> int:
    """1-based line of a header key."""
    return head.key_lines.get(key, 1)


def file_length_scale(head: QtmHead) -> tuple[float, str]:
    """Metres per file unit; QTM writes mm, a ``MARKER_UNITS``-like key may say otherwise."""
    for key in _UNIT_KEYS:
        values = head.keys.get(key)
        if values:
            unit = values[0].strip()
            try:
                return length_scale(unit), unit
            except ValueError as e:
                raise head.bad(f"{key} {e}", key_line(head, key)) from None
    return 1e-3, "mm"


def export_meta(head: QtmHead, fmt: str, unit: str) -> dict[str, Any]:
    """A series' ``meta``: its format, the file's length unit and the header (its keys but the
    name lists)."""
    header = {k: (v[0] if len(v) == 1 else list(v)) for k, v in head.keys.items()
              if k not in _LIST_KEYS}
    return {"format": fmt, "units_in_file": unit, "header": header}

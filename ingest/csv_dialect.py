"""Delimited text logs in any common dialect: the delimiter (, ; tab | or spaces), the decimal
mark (. or ,), quoted fields, ``#`` comment lines, and a preamble of metadata lines before the
column line (``Frequency = 1000``, ``Force Units,N``), as loggers and vendors' tools write them.

``sniff_dialect`` finds the dialect from the first lines: the data rows are the lines whose
fields are mostly numbers, the delimiter the one that splits them into the same number of
number fields, the decimal mark the one those numbers use, the column line the last line before
them. Where that cannot decide (decimal commas and points in one file), session.toml states it
(``force.delimiter``, ``force.decimal``). ``read_text_table`` reads the whole file with pandas'
C parser in that dialect into a :class:`~ingest.log_table.LogTable`; a file without a column
line gets its columns numbered (time first, then signals 1, 2, ...).
"""

from __future__ import annotations

import csv
import io
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from core.errors import BadInput
from core.units import time_unit_in_name, unit_in_name
from ingest.log_table import LogTable
from ingest.sniff import check_last_line

DECIMALS = (".", ",")
_HEAD_LINES = 200
_NUMBER = re.compile(r"[+-]?(\d+([.,]\d*)?|[.,]\d+)([eE][+-]?\d+)?")
_COMMA_DECIMAL = re.compile(r"[+-]?\d*,\d+([eE][+-]?\d+)?")
_POINT_DECIMAL = re.compile(r"[+-]?\d*\.\d+([eE][+-]?\d+)?")
_META = re.compile(r"^\s*([A-Za-z][\w /().\-]*?)\s*[=:]\s*(.*?)\s*$")
_PANDAS_LINE = re.compile(r"in line (\d+)")


@dataclass
class Dialect:
    """How a delimited text log is written."""

    delimiter: str                  # one character; " " means any run of spaces or tabs
    decimal: str                    # "." or ","
    encoding: str                   # utf-8-sig or cp1252
    header_line: int | None         # 0-based line of the column line; None: no column line
    data_line: int                  # 0-based line of the first data row
    header: list[str] = field(default_factory=list)      # the column line's fields
    metadata: dict[str, str] = field(default_factory=dict)   # key -> value of the preamble
    comment: str | None = None      # the comment mark its comment lines start with
    units_row: list[str] = field(default_factory=list)   # a line of units under the names
    data_rows: int = 0              # rows of data among the lines sniffed

    def describe(self) -> dict[str, object]:
        return {"delimiter": {"\t": "tab", " ": "whitespace"}.get(self.delimiter,
                                                                  self.delimiter),
                "decimal": self.decimal, "encoding": self.encoding,
                "header_line": None if self.header_line is None else self.header_line + 1,
                "first_data_line": self.data_line + 1}


# ---------------------------------------------------------------------------- sniffing


def _head_lines(path: str | Path) -> tuple[list[str], str]:
    raw = open(path, "rb").read(1 << 16)
    for enc in ("utf-8-sig", "cp1252"):
        try:
            text = raw.decode(enc)
            break
        except UnicodeDecodeError as e:
            if enc == "utf-8-sig" and e.start >= len(raw) - 3:
                text = raw[: e.start].decode(enc)
                break
    else:
        raise BadInput(path, "not a text file in UTF-8 or Windows-1252")
    lines = text.splitlines()
    if len(raw) == 1 << 16 and lines:
        lines = lines[:-1]                            # the last line may be cut by the read
    return lines[:_HEAD_LINES], enc


def split_fields(line: str, delimiter: str) -> list[str]:
    """A line's fields, quotes removed, each stripped."""
    if delimiter == " ":
        return line.split()
    return [f.strip() for f in next(csv.reader(io.StringIO(line), delimiter=delimiter,
                                               skipinitialspace=True), [])]


def _is_number(token: str) -> bool:
    return bool(_NUMBER.fullmatch(token)) or token.lower() in ("nan", "inf", "-inf")


_CLOCK = re.compile(r"(\d{1,4}[-/.]\d{1,2}[-/.]\d{1,4}[ T]?)?\d{1,2}:\d{2}(:\d{2}([.,]\d+)?)?"
                    r"\s*([AaPp][Mm]|Z|[+-]\d{2}:?\d{2})?")
_HEX = re.compile(r"0[xX][0-9a-fA-F]+")


def _is_value(token: str) -> bool:
    """A data value: a number, a date and clock time, or a hex word (a status)."""
    return _is_number(token) or bool(_CLOCK.fullmatch(token) or _HEX.fullmatch(token))


def _numeric_share(fields: list[str]) -> float:
    used = [f for f in fields if f]
    return sum(map(_is_value, used)) / len(used) if used else 0.0


_COMMENTS = ("#", "%", "//")
_EXCEL_SEP = re.compile(r'^"?sep=(.)"?\s*$')


def _is_comment(line: str) -> bool:
    return line.lstrip().startswith(_COMMENTS)


def _comment_mark(lines: list[str]) -> str | None:
    """The first character of the comment lines (pandas takes one), if the file has any."""
    marks = {x.lstrip()[:1] for x in lines if _is_comment(x)}
    return marks.pop() if len(marks) == 1 else None


def _is_units_row(fields: list[str]) -> bool:
    """A line of units under the column names ("s", "V", "(N)", "[N-mm]", blanks)."""
    used = [f.strip("()[] ") for f in fields if f.strip("()[] ")]
    return len(used) >= max(1, len(fields) // 2) and all(
        unit_in_name(f"x ({u})") or time_unit_in_name(f"x ({u})") for u in used)


def _data_start(rows: list[list[str]]) -> int | None:
    """The first row from which the rows are data: it mostly numbers, and most of the few
    rows after it (one bad value further down is the reader's to report, with its line)."""
    for i in range(len(rows)):
        near = [_numeric_share(r) > 0.5 for r in rows[i:i + 5] if r]
        if near and near[0] and sum(near) > len(near) / 2:
            return i
    return None


def _score(lines: list[str], delimiter: str) -> float:
    """How well ``delimiter`` splits the last lines into rows of numbers of one width."""
    rows = [split_fields(x, delimiter) for x in lines[-20:]]
    widths = [len(r) for r in rows]
    width = max(set(widths), key=widths.count)
    if width < 2:
        return 0.0
    same = widths.count(width) / len(widths)
    return same * sum(_numeric_share(r) for r in rows) / len(rows)


def _decimal(path: str | Path, rows: list[list[str]], delimiter: str) -> str:
    tokens = [f for r in rows for f in r if _is_number(f)]
    comma = any(_COMMA_DECIMAL.fullmatch(t) for t in tokens)
    point = any(_POINT_DECIMAL.fullmatch(t) for t in tokens)
    if comma and point:
        raise BadInput(path, "numbers are written with both decimal commas and points: state "
                             "force.decimal (\".\" or \",\") in session.toml")
    return "," if comma else "."


def sniff_dialect(path: str | Path, delimiter: str | None = None,
                  decimal: str | None = None) -> Dialect:
    """The dialect of a delimited text log; ``delimiter`` and ``decimal`` (session.toml) win
    over what the file suggests."""
    lines, enc = _head_lines(path)
    body = [x for x in lines if x.strip() and not _is_comment(x)]
    if not body:
        raise BadInput(path, "holds no rows (only blank or # comment lines)")
    excel = _EXCEL_SEP.match(body[0])
    if delimiter is None and excel:               # Excel's "sep=;" first line
        delimiter = excel.group(1)
    if delimiter is None:
        scores = {d: _score(body, d) for d in (",", ";", "\t", "|", " ")}
        delimiter = max(scores, key=lambda d: scores[d])
        if scores[delimiter] == 0.0:
            raise BadInput(path, "cannot find the rows of numbers of a log: no delimiter "
                                 "(, ; tab | spaces) splits the last lines into the same "
                                 "number of fields; state force.delimiter in session.toml")
    numbered = [(i, x) for i, x in enumerate(lines) if x.strip() and not _is_comment(x)]
    rows = [split_fields(x, delimiter) for _, x in numbered]
    start = _data_start(rows)
    if start is None:
        raise BadInput(path, f"no rows of numbers split by {delimiter!r} in the first "
                             f"{len(lines)} lines")
    if decimal is None:
        decimal = _decimal(path, rows[start:start + 50], delimiter)
    if delimiter == decimal:
        raise BadInput(path, f"the delimiter and the decimal mark are both {delimiter!r}")
    header_at = start - 1 if start > 0 else None
    if header_at is not None and len([f for f in rows[header_at] if f]) == 2 < len(rows[start]):
        header_at = None                      # a "key, value" line, not the column line
    units_row: list[str] = []
    if header_at is not None and header_at >= 1 and _is_units_row(rows[header_at]) and \
            len(rows[header_at - 1]) == len(rows[header_at]):
        units_row, header_at = rows[header_at], header_at - 1
    metadata: dict[str, str] = {}
    for r in rows[:start if header_at is None else header_at]:
        metadata.update(_metadata(r))
    if header_at is not None:                 # "Frequency = 1000" among the column names
        metadata.update({k: v for f in rows[header_at] for k, v in _metadata([f]).items()
                         if is_metadata_field(f)})
    return Dialect(delimiter=delimiter, decimal=decimal, encoding=enc,
                   header_line=None if header_at is None else numbered[header_at][0],
                   data_line=numbered[start][0],
                   header=rows[header_at] if header_at is not None else [],
                   metadata=metadata, comment=_comment_mark(lines), units_row=units_row,
                   data_rows=len(rows) - start)


def _metadata(fields: list[str]) -> dict[str, str]:
    """``key = value`` / ``key: value`` fields, or a ``key, value`` pair of fields."""
    out = {}
    for f in fields:
        m = _META.match(f)
        if m and m.group(2):
            out[m.group(1).strip()] = m.group(2)
    if not out and len([f for f in fields if f]) == 2 and not _is_number(fields[0]):
        out[fields[0]] = fields[1]
    return out


def is_metadata_field(text: str) -> bool:
    m = _META.match(text)
    return bool(m and m.group(2))


# ---------------------------------------------------------------------------- reading


def _width(path: str | Path, d: Dialect) -> tuple[int, list[str]]:
    """Fields of a data row (a trailing empty field left out) and the first data row."""
    rows = []
    with open(path, encoding=d.encoding, errors="replace") as f:
        for i, line in enumerate(f):
            if i >= d.data_line and line.strip() and not _is_comment(line):
                rows.append(split_fields(line.rstrip("\r\n"), d.delimiter))
                if len(rows) == 20:
                    break
    widths = [len(r) - (1 if len(r) > 1 and not r[-1] else 0) for r in rows]
    return max(set(widths), key=widths.count), rows[0]


def _names(path: str | Path, d: Dialect, width: int) -> tuple[list[str], list[int]]:
    """Column names and the fields they are (metadata fields of the column line dropped)."""
    if d.header_line is None:
        return ["time", *(str(i) for i in range(1, width))], list(range(width))
    fields = list(d.header)
    while fields and not fields[-1] and len(fields) > width:      # a trailing delimiter
        fields.pop()
    keep = [i for i, f in enumerate(fields) if not is_metadata_field(f)]
    if len(keep) == len(fields):                 # a plain column line: pandas checks rows
        while len(fields) > 1 and not fields[-1]:
            fields.pop()
        cols, names = list(range(len(fields))), fields
    elif len(keep) == width:
        cols, names = list(range(width)), [fields[i] for i in keep]
    elif len(fields) == width:
        cols, names = keep, [fields[i] for i in keep]
    else:
        raise BadInput(path, f"the column line names {len(keep)} columns but the rows have "
                             f"{width} fields", where=f"line {d.header_line + 1}")
    names = [n or f"column {c + 1}" for n, c in zip(names, cols, strict=True)]
    dups = sorted({n for n in names if names.count(n) > 1})
    if dups:
        raise BadInput(path, f"duplicate column name(s) in the header: {', '.join(dups)}",
                       where=f"line {d.header_line + 1}")
    return names, cols


def _read(path: str | Path, d: Dialect, plain_header: bool, n: int) -> pd.DataFrame:
    """pandas' C parser over the rows (with the column line when it is a plain one, so that a
    first row with an extra field is caught as pandas sees it)."""
    sep = r"\s+" if d.delimiter == " " else d.delimiter
    kw = {"header": 0, "skiprows": d.header_line} if plain_header else \
        {"header": None, "skiprows": d.data_line}
    where = d.data_line + 1
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", pd.errors.ParserWarning)
            return pd.read_csv(path, sep=sep, decimal=d.decimal, quotechar='"',
                               skipinitialspace=True, comment=d.comment,
                               index_col=False, encoding=d.encoding,
                               engine="c" if d.delimiter != " " else "python", **kw)
    except pd.errors.ParserWarning:
        raise BadInput(path, f"row has more fields than the {n} of the header",
                       where=f"line {where}") from None
    except (ValueError, pd.errors.ParserError, UnicodeDecodeError) as e:
        line = _PANDAS_LINE.search(str(e))
        offset = (d.header_line or 0) if plain_header else d.data_line
        at = None if not line else int(line.group(1)) + offset
        raise BadInput(path, f"cannot parse the log ({str(e).strip()})",
                       where=f"line {at}" if at else None) from None


def read_text_table(path: str | Path, d: Dialect, fmt: str = "force_csv") -> LogTable:
    """The whole log in dialect ``d``: every row must have the first row's number of fields
    (a trailing delimiter on every row is allowed), and the file must not end mid-row."""
    width, first = _width(path, d)
    names, cols = _names(path, d, width)
    plain = d.header_line is not None and not any(map(is_metadata_field, d.header)) and \
        not d.units_row
    df = _read(path, d, plain, len(names))
    if plain and df.shape[1] == len(names) + 1 and df.iloc[:, -1].isna().all():
        df = df.iloc[:, :-1]                 # a trailing delimiter on the column line too
    if plain and df.shape[1] != len(names):
        raise BadInput(path, f"the header names {len(names)} columns, pandas found "
                             f"{df.shape[1]} (quoted separators?)",
                       where=f"line {(d.header_line or 0) + 1}")   # plain: it has one
    extra = df.iloc[:, width:]
    if not plain and (df.shape[1] < width or extra.notna().any().any()):
        raise BadInput(path, f"rows have {df.shape[1]} fields, the first row {width}",
                       where=f"line {d.data_line + 1}")
    if d.delimiter != " ":
        check_last_line(path, d.delimiter, len(first), first, d.data_line + len(df))
    columns = {n: _column(df.iloc[:, c], d.decimal) for n, c in zip(names, cols, strict=True)}
    units = {n: u for n in names if (u := unit_in_name(n))}
    for n, c in zip(names, cols, strict=True):
        u = d.units_row[c].strip("()[] ") if c < len(d.units_row) else ""
        if u and unit_in_name(f"x ({u})"):
            units[n] = u
        elif u and time_unit_in_name(f"x ({u})"):
            units[n] = str(time_unit_in_name(f"x ({u})"))
    return LogTable(format=fmt, columns=columns, where=lambda i: f"line {d.data_line + 1 + i}",
                    units=units, time="time" if d.header_line is None else None,
                    details={"dialect": d.describe(),
                             **({"metadata": d.metadata} if d.metadata else {})})


def _column(s: pd.Series, decimal: str) -> pd.Series:
    """A column as pandas read it; decimal commas inside quotes (which pandas' ``decimal``
    leaves alone) become points."""
    if decimal == "," and (s.dtype == object or pd.api.types.is_string_dtype(s)):
        text = s.str.strip()
        pointed = text.str.replace(",", ".", regex=False)
        converted = pd.to_numeric(pointed, errors="coerce")
        if converted.notna().sum() == text.notna().sum():
            return converted
        return pointed              # the numbers readable, the text left for the check
    return s

"""Cheap content checks the file readers share, before any reader parses a file.

``sniff`` names a file's container from its first bytes (magic numbers, MAT headers), and
``check_last_line`` tells a complete text export from one cut short. Every reader in
:mod:`ingest` stands on these; :mod:`ingest.detect` builds the format names on top of them.
"""

from __future__ import annotations

import re
import struct
from pathlib import Path

from core.errors import BadInput

_HDF5 = b"\x89HDF\r\n\x1a\n"
_HEAD = 4096


def read_head(path: str | Path, n: int = _HEAD) -> bytes:
    try:
        with open(path, "rb") as f:
            return f.read(n)
    except IsADirectoryError:
        raise BadInput(path, "is a folder, not a file") from None
    except FileNotFoundError:
        raise BadInput(path, "no such file") from None
    except OSError as e:
        raise BadInput(path, f"cannot read ({e.strerror or e})") from None


def _is_mat(head: bytes) -> bool:
    """MAT v5/v7/v7.3: bytes 126-127 are the endian mark, 124-125 the version (0x0100 or 0x0200
    for v7.3), as scipy checks; the descriptive text before them varies with the writer."""
    if len(head) < 128 or head[126:128] not in (b"IM", b"MI"):
        return False
    version = int.from_bytes(head[124:126], "little" if head[126:128] == b"IM" else "big")
    return version in (0x0100, 0x0200) and head[:1] != b"\x00"


def _is_mat4(head: bytes) -> bool:
    """MAT Level 4 (Simulink's To File and xPC/Speedgoat file logs of old): no text header;
    the first variable's header is five int32 (type MOPT, rows, columns, imaginary flag, name
    length), then its NUL-terminated name."""
    if len(head) < 21:
        return False
    for order in ("<", ">"):
        mopt, rows, cols, imag, namlen = struct.unpack(order + "5i", head[:20])
        m, o, p, t = mopt // 1000, mopt // 100 % 10, mopt // 10 % 10, mopt % 10
        name = head[20:20 + namlen]
        if (0 <= mopt < 5000 and m == (0 if order == "<" else 1) and o == 0 and p <= 5
                and t <= 2 and rows >= 0 and cols >= 0 and imag in (0, 1)
                and 2 <= namlen <= 64 and len(name) == namlen and name.endswith(b"\x00")
                and re.fullmatch(rb"[A-Za-z][A-Za-z0-9_]*", name[:-1])):
            return True
    return False


def _is_c3d(head: bytes) -> bool:
    """C3D: byte 2 is 0x50 and the parameter section it points to names a processor type."""
    if len(head) < 512 or head[1] != 0x50 or head[0] < 2:
        return False
    start = (head[0] - 1) * 512
    return len(head) >= start + 4 and head[start + 3] in (84, 85, 86)


def head_text(head: bytes) -> str | None:
    """The head as text, or None for binary content (NUL bytes, invalid encodings)."""
    if b"\x00" in head:
        return None
    try:
        return head.decode("utf-8")
    except UnicodeDecodeError as e:
        if e.start >= len(head) - 3:      # a multi-byte character cut by the head's end
            return head[: e.start].decode("utf-8")
    try:
        return head.decode("cp1252")
    except UnicodeDecodeError:
        return None


def sniff(path: str | Path) -> str:
    """The container of a file from its first bytes.

    One of ``mcap``, ``mat73`` (HDF5 with a MATLAB userblock), ``hdf5``, ``mat5`` (MAT v5/v6/v7),
    ``mat4`` (MAT Level 4),
    ``parquet``, ``c3d``, ``xml``, ``json``, ``text``, ``empty`` or ``binary``.
    """
    head = read_head(path)
    if not head:
        return "empty"
    if head.startswith(b"\x89MCAP"):
        return "mcap"
    if head.startswith(_HDF5):
        return "hdf5"
    if _is_mat(head):                     # 128-byte MAT header: text, version, endian mark
        return "mat73" if head[512:520] == _HDF5 else "mat5"
    if any(head[o:o + 8] == _HDF5 for o in (512, 1024, 2048)):
        return "hdf5"                     # HDF5 behind a user block that is not MATLAB's
    if _is_mat4(head):
        return "mat4"
    if head.startswith(b"PAR1"):
        return "parquet"
    if _is_c3d(head):
        return "c3d"
    text = head_text(head)
    if text is None:
        return "binary"
    start = text.lstrip("\ufeff \t\r\n")[:1]
    return {"<": "xml", "{": "json", "[": "json"}.get(start, "text")


def check_last_line(
    path: str | Path, sep: str, n_fields: int, reference: list[str], line_no: int
) -> None:
    """A text export must not end in the middle of a row.

    A last line without a line break is accepted only when it has all ``n_fields`` fields and
    its last field, when a plain decimal number, has as many decimals as in the row before:
    exporters write a fixed number of decimals, so a shorter number was cut. The rule applies
    only where the file shows fixed decimals: the previous row and ``reference`` (another data
    row) agree on them.
    """
    size = Path(path).stat().st_size
    with open(path, "rb") as f:
        f.seek(max(0, size - 65536))
        tail = f.read()
    if not tail or tail.endswith(b"\n"):
        return
    lines = tail.decode("utf-8", "replace").split("\n")
    last = lines[-1].rstrip("\r").split(sep)
    where = f"line {line_no}"
    if len(last) != n_fields:
        raise BadInput(path, f"file ends in the middle of a row ({len(last)} of {n_fields} "
                             "fields): truncated", where=where)
    previous = lines[-2].rstrip("\r").split(sep) if len(lines) > 2 else []
    fixed = _decimals(previous[-1]) if len(previous) == n_fields else None
    if fixed is None or len(reference) != n_fields or _decimals(reference[-1]) != fixed:
        return                                   # no fixed number of decimals to judge by
    cut = _decimals(last[-1])
    if cut is not None and cut < fixed:
        raise BadInput(path, f"file ends in the middle of a number ({last[-1].strip()!r}): "
                             "truncated", where=where)


_PLAIN = re.compile(r"[+-]?\d+(?:\.(\d*))?")


def _decimals(token: str) -> int | None:
    """Digits after the decimal point of a plain decimal number (``-12.250``: 3); None for
    anything else (gaps, ``NaN``, exponents, text)."""
    m = _PLAIN.fullmatch(token.strip())
    if m is None:
        return None
    return len(m.group(1) or "")

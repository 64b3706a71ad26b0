"""The data block of a QTM TSV export (3D, 6D or analog): its rows parsed into float64 arrays.

pyarrow's C++ CSV reader parses the block (fast, and strict: every row must have the same
number of fields); gaps (``NaN``, ``null``, empty cells) become NaN. What the header claims
(``NO_OF_FRAMES``) is checked against the rows before it is trusted, and a parse error is traced
back to the first bad line.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pyarrow as pa
import pyarrow.csv as pcsv

from core.errors import BadInput
from ingest.qtm_header import count
from ingest.qtm_scan import GAPS, QtmHead, decode, is_value
from ingest.sniff import check_last_line


def parse_block(
    head: QtmHead, n_fields: int, time_col: int | None, value_cols: list[int],
    block: Callable[[np.ndarray], None] | None = None,
) -> tuple[np.ndarray | None, np.ndarray]:
    """Parse the data block (rows of ``n_fields`` fields) into float64 arrays.

    Returns the Time column (or None) and ``values[row, i]`` = column ``value_cols[i]``, C-order.
    pyarrow parses the block batch by batch and turns each batch into a row-major array in C++;
    ``block`` post-processes each batch's rows in place while they are still in cache. Only one
    parsed batch is alive at a time, so memory stays near the size of the result.
    """
    require_data(head)
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
                    null_values=GAPS, strings_can_be_null=True,
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


def _capacity(head: QtmHead, n_fields: int) -> int:
    """Rows to allocate: NO_OF_FRAMES, but never more than the bytes left could hold (a row
    takes at least ``n_fields`` bytes), so a lying header cannot make us allocate."""
    left = head.path.stat().st_size - head.offset
    bound = left // max(n_fields, 1) + 1
    claimed = head.number("NO_OF_FRAMES")
    if claimed is None or not (0 < claimed < bound):
        return min(bound, 65536)
    return int(claimed)


def _grow(head: QtmHead, values: np.ndarray, times: np.ndarray | None,
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


def require_data(head: QtmHead) -> None:
    """Refuse a file whose header is followed by no data row."""
    if head.first is None:
        frames = head.scalar("NO_OF_FRAMES")
        raise head.bad(f"truncated: no data rows (NO_OF_FRAMES says {frames})"
                       if frames not in (None, "0") else "no data rows")


def _diagnose(head: QtmHead, n_fields: int, wanted: list[int], err: str) -> BadInput:
    """Find the first bad line of the data block (slow; runs only after a parse error)."""
    with open(head.path, "rb") as f:
        f.seek(head.offset)
        line_no = head.first_line - 1
        for raw in f:
            line_no += 1
            text = decode(raw).rstrip("\r\n")
            if not text.strip():
                continue
            fields = text.split("\t")
            if len(fields) != n_fields:
                end = "" if raw.endswith(b"\n") else " (the file ends here: truncated)"
                return head.bad(f"row has {len(fields)} fields, expected {n_fields}{end}",
                                line_no)
            for i in wanted:
                if not is_value(fields[i]):
                    return head.bad(f"{fields[i].strip()!r} in column {i + 1} is not a number",
                                    line_no)
    return head.bad(f"cannot parse the data block ({err})")


def _check_rows(head: QtmHead, n_rows: int, n_fields: int) -> None:
    """The row count must match NO_OF_FRAMES and the last row must be complete."""
    last = head.first_line + n_rows - 1
    check_last_line(head.path, "\t", n_fields, head.first or [], last)
    claimed = head.scalar("NO_OF_FRAMES")
    frames = None if claimed is None else count(claimed)
    if frames is None:                           # absent (checked by check_header)
        return
    if n_rows < frames:
        raise head.bad(f"truncated: NO_OF_FRAMES says {frames} but the file has {n_rows} data "
                       "rows", last)
    if n_rows > frames:
        raise head.bad(f"NO_OF_FRAMES says {frames} but the file has {n_rows} data rows",
                       head.first_line + frames)

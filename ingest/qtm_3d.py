"""QTM TSV 3D exports: marker trajectories, in every layout QTM has written.

The markers are those of ``MARKER_NAMES``; a column line (``Frame Time <name> X ...``), where
there is one, must name them in that order, else the rows hold ``X Y Z`` per marker, optionally
after Frame and Time. Gaps (``NaN``, ``null``, empty cells, an exact ``0 0 0`` triple) become
NaN; millimetres become metres.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from core.series import MarkerSeries
from ingest.qtm_block import parse_block, require_data
from ingest.qtm_header import column_problem, count, finite
from ingest.qtm_scan import (
    QtmHead,
    check_header,
    check_row_width,
    export_meta,
    file_length_scale,
    is_value,
    scan_export,
)
from ingest.qtm_timing import events, frame_times


def read_qtm_3d(path: str | Path) -> MarkerSeries:
    """Read a QTM TSV 3D export: marker positions in metres, NaN where missing."""
    head = scan_export(path, "MARKER_NAMES", "3D")
    return read_3d(head)


def read_3d(head: QtmHead) -> MarkerSeries:
    """The markers of a scanned export whose header lists ``MARKER_NAMES``."""
    names = check_header(head, "MARKER_NAMES", "NO_OF_MARKERS")
    types = head.keys.get("TRAJECTORY_TYPES")
    scale, unit = file_length_scale(head)
    require_data(head)
    n_fields, time_col, cols = _layout_3d(head, names)

    def to_metres(block: np.ndarray) -> None:
        xyz = block.reshape(len(block), len(names), 3)
        xyz *= scale
        x, y, z = xyz[..., 0], xyz[..., 1], xyz[..., 2]
        missing = np.isnan(x + y + z) | ((x == 0) & (y == 0) & (z == 0))   # NaN, or 0 0 0
        xyz[missing] = np.nan

    t, values = parse_block(head, n_fields, time_col, [int(c) for c in cols.ravel()],
                            to_metres)
    n = len(values)
    time_ns, rate = frame_times(head, t, n)
    positions = values.reshape(n, len(names), 3)
    meta = export_meta(head, "qtm_tsv_3d", unit)
    if types is not None:
        meta["trajectory_types"] = [t.strip() for t in types]
    return MarkerSeries(source=str(head.path), time_ns=time_ns, labels=names,
                        positions=positions, rate_hz=float(rate), events=events(head, rate),
                        meta=meta)


def _layout_3d(head: QtmHead, names: list[str]) -> tuple[int, int | None, np.ndarray]:
    """Fields per row, the Time column (or None) and the (M, 3) columns of X, Y, Z."""
    assert head.first is not None
    if head.labels is not None:
        return _labelled_layout(head, names)
    n_fields, m = len(head.first), len(names)
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


def _labelled_layout(head: QtmHead, names: list[str]) -> tuple[int, int | None, np.ndarray]:
    """:func:`_layout_3d` of a file with a column line: each marker's columns by their labels."""
    assert head.first is not None and head.labels is not None
    n_fields, m = len(head.first), len(names)
    labels = [s.strip() for s in head.labels]
    check_row_width(head, labels)
    index: dict[str, int] = {}
    for i, label in enumerate(labels):
        index.setdefault(label, i)
    if "Frame" not in index and not any(f"{n} X" in index for n in names):
        token = next(x for x in labels if not is_value(x))
        raise head.bad(f"{token!r} is not a number (and this is no column line)",
                       head.labels_line)
    problem = column_problem(labels, names)
    if problem is not None:
        col, what = problem
        raise head.bad(f"{what} (column {col + 1})", head.labels_line)
    cols = np.empty((m, 3), dtype=np.int64)
    for j, name in enumerate(names):
        for k, axis in enumerate("XYZ"):
            found = index.get(f"{name} {axis}")
            if found is None:
                raise head.bad(f"column line has no column '{name} {axis}' for marker "
                               f"{name!r} of MARKER_NAMES", head.labels_line)
            cols[j, k] = found
    return n_fields, index.get("Time"), cols

"""QTM TSV 6D exports: rigid bodies, in every layout QTM has written.

Each body of ``BODY_NAMES`` takes 16 fields of a row (position, Euler angles, residual, the 9
rotation matrix entries), 17 where QTM separates bodies by an empty field; newer exports name
every field on a column line (``Frame Time <body> X ...``), old ones label one group for all
bodies (`` X Y Z Yaw ...``) or none at all. A lost body (a NaN, residual -1, or an all-zero
rotation) becomes NaN; millimetres become metres.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from core.series import BodySeries
from ingest.qtm_block import parse_block, require_data
from ingest.qtm_scan import (
    QtmHead,
    check_header,
    check_row_width,
    export_meta,
    file_length_scale,
    scan_export,
)
from ingest.qtm_timing import events, frame_times

# one body in a 6D row: 16 values; where each sits when the file has no label line
_BODY_FIELDS = 16
_BODY_DEFAULT = {"X": 0, "Y": 1, "Z": 2, "Residual": 6, **{f"Rot[{k}]": 7 + k for k in range(9)}}


def read_qtm_6d(path: str | Path) -> BodySeries:
    """Read a QTM TSV 6D export: body positions (m), rotation matrices, residuals (m)."""
    head = scan_export(path, "BODY_NAMES", "6D")
    return read_6d(head)


def read_6d(head: QtmHead) -> BodySeries:
    """The bodies of a scanned export whose header lists ``BODY_NAMES``."""
    names = check_header(head, "BODY_NAMES", "NO_OF_BODIES")
    scale, unit = file_length_scale(head)
    require_data(head)
    n_fields, time_col, lead, stride, off = _layout_6d(head, names)
    tokens = ["X", "Y", "Z", "Residual", *(f"Rot[{k}]" for k in range(9))]
    cols = np.array([[lead + stride * b + off[t] for t in tokens] for b in range(len(names))])
    t, flat = parse_block(head, n_fields, time_col, [int(c) for c in cols.ravel()])
    n = len(flat)
    time_ns, rate = frame_times(head, t, n)
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
                      rate_hz=float(rate), events=events(head, rate),
                      meta=export_meta(head, "qtm_tsv_6d", unit))


def _body_offsets(head: QtmHead, labels: list[str]) -> dict[str, int]:
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


def _check_body_labels(head: QtmHead, names: list[str], lead: int, stride: int) -> None:
    """The label line must describe the bodies of BODY_NAMES, in order, one group of 16 labels
    each laid out as the first (``<body> X  Y  Z  Roll ... Rot[8]``, the body's name on any of
    them), or, in old exports, one unnamed group for all bodies. A column line (``Frame Time
    ...``) must be as wide as the rows."""
    labels = [s.strip() for s in head.labels or []]
    shared = labels[0] != "Frame" and len(labels) <= lead + _BODY_FIELDS and len(names) > 1
    if not shared:
        check_row_width(head, labels)
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


def _layout_6d(head: QtmHead, names: list[str]) -> tuple[int, int | None, int, int,
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

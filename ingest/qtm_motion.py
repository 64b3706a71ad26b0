"""A QTM TSV motion export, 3D (:mod:`ingest.qtm_3d`) or 6D (:mod:`ingest.qtm_6d`), read by
what its header lists (``MARKER_NAMES`` or ``BODY_NAMES``) whatever its name says."""

from __future__ import annotations

from pathlib import Path

from core.series import BodySeries, MarkerSeries
from ingest.qtm_3d import read_3d
from ingest.qtm_6d import read_6d
from ingest.qtm_scan import scan


def read_qtm_tsv(path: str | Path) -> MarkerSeries | BodySeries:
    """Read a QTM TSV export: 3D (``MARKER_NAMES``) or 6D (``BODY_NAMES``), found by its keys."""
    head = scan(path)
    if "MARKER_NAMES" in head.keys and "BODY_NAMES" in head.keys:
        raise head.bad("header has both MARKER_NAMES and BODY_NAMES")
    if "MARKER_NAMES" in head.keys:
        return read_3d(head)
    if "BODY_NAMES" in head.keys:
        return read_6d(head)
    kind = head.scalar("DATA_INCLUDED") or "unknown"
    raise head.bad(f"unsupported QTM TSV export (DATA_INCLUDED {kind}; no MARKER_NAMES or "
                   "BODY_NAMES)")

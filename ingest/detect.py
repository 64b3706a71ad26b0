"""What is in a file, judged by its content (magic bytes, headers), not only by its extension.

``detect_format`` names every format the pipeline reads or writes (force logs in text: plain or
dialect CSV, ATI's DAQ F/T and Net F/T logs, QTM force-plate exports); ``read_mocap`` reads any of
the 3D marker exports (QTM TSV 3D, C3D, QTM MAT) and ``read_analog`` the mocap system's analog
channels (C3D, QTM analog TSV) with the reader its content calls for. The
container test underneath is :func:`ingest.sniff.sniff`.
"""

from __future__ import annotations

from pathlib import Path

from core.errors import BadInput
from core.series import MarkerSeries
from ingest.analog import AnalogExport
from ingest.c3d import read_c3d, read_c3d_analog
from ingest.force_log import text_log_format
from ingest.qtm_3d import read_qtm_3d
from ingest.qtm_analog import read_qtm_analog
from ingest.qtm_force_plate import looks_like_force_plate
from ingest.qtm_mat import is_qtm_mat, read_qtm_mat
from ingest.qtm_scan import looks_like_qtm_tsv, parse_qtm_header
from ingest.sniff import head_text, read_head, sniff

FORMATS = (
    "qtm_tsv_3d", "qtm_tsv_6d", "qtm_tsv_analog", "qtm_tsv_force", "c3d", "qtm_mat",
    "force_csv", "force_ati_daq", "force_ati_netft", "force_mat", "force_parquet", "ati_cal",
    "mcap", "hdf5", "json", "session_toml",
)

def detect_format(path: str | Path) -> str:
    """The format of ``path`` (one of ``FORMATS``) from its content; unknown -> BadInput."""
    kind = sniff(path)
    if kind in ("mcap", "hdf5", "c3d", "json"):
        return kind
    if kind == "parquet":
        return "force_parquet"
    if kind in ("mat5", "mat73"):
        try:
            return "qtm_mat" if is_qtm_mat(path) else "force_mat"
        except RuntimeError as e:          # h5py on a damaged v7.3 file
            raise BadInput(path, f"cannot read MAT file ({e})") from None
    if kind == "mat4":
        return "force_mat"
    head = head_text(read_head(path)) or ""
    if kind == "xml" and "<FTSensor" in head:
        return "ati_cal"
    if kind == "text" and _is_session_toml(head):
        return "session_toml"
    if kind == "text":
        fmt = _text_format(path, head)
        if fmt:
            return fmt
    raise BadInput(path, "unknown format")


def _is_session_toml(head: str) -> bool:
    """A session.toml declares its schema, or at least the [mocap] and [force] tables."""
    return "phantom.session" in head or ("[mocap]" in head and "[force]" in head)


def _text_format(path: str | Path, head: str) -> str | None:
    if looks_like_force_plate(head):
        return "qtm_tsv_force"
    if looks_like_qtm_tsv(head):
        header = parse_qtm_header(path)
        if "MARKER_NAMES" in header:
            return "qtm_tsv_3d"
        if "BODY_NAMES" in header:
            return "qtm_tsv_6d"
        if "CHANNEL_NAMES" in header:
            return "qtm_tsv_analog"
        return None
    try:
        return text_log_format(path, bare_rows=_BARE_ROWS)
    except BadInput:
        return None


_BARE_ROWS = 10     # rows of numbers without a column line that content alone calls a log


def read_mocap(path: str | Path) -> MarkerSeries:
    """Read any 3D marker export (QTM TSV 3D, C3D, QTM MAT) into a ``MarkerSeries``."""
    fmt = detect_format(path)
    if fmt == "qtm_tsv_6d":
        raise BadInput(path, "is a QTM 6D (rigid body) export, not a 3D marker export")
    if fmt == "qtm_tsv_3d":
        return read_qtm_3d(path)
    if fmt == "c3d":
        return read_c3d(path)
    if fmt == "qtm_mat":
        return read_qtm_mat(path)
    raise BadInput(path, f"not a 3D marker export (found {fmt}); expected QTM TSV 3D, C3D or MAT")


ANALOG_FORMATS = ("c3d", "qtm_tsv_analog")


def read_analog(path: str | Path) -> AnalogExport:
    """Read the analog channels of a mocap export (C3D or QTM analog TSV)."""
    fmt = detect_format(path)
    if fmt == "c3d":
        return read_c3d_analog(path)
    if fmt == "qtm_tsv_analog":
        return read_qtm_analog(path)
    raise BadInput(path, f"not an export with analog channels (found {fmt}); expected C3D or "
                         "a QTM analog TSV export")

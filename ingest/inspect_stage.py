"""The inspect stage runner: one summary for any lab file and any file the pipeline writes.

The summary is a dict with the same keys for every format (``None`` where a key does not apply),
so scripts can rely on them (``pipeline inspect FILE --json``):

``path``, ``format`` (the :func:`ingest.detect.detect_format` name, or ``rrd``), ``frames``,
``rate_hz``, ``duration_s`` (frames x mean sample interval), ``markers``, ``bodies``,
``channels`` (force-log channels; an analog export's channel names), ``missing_samples``
(marker or body samples with no position; None for a force log: one with a missing value is
bad input), ``holes`` (the stretches of samples a lab file's clock skips, each in words:
:mod:`core.holes`), ``units`` (quantity -> unit as stored in the file), ``events`` ([label,
seconds]), ``analog`` (the analog channels of a C3D or QTM analog TSV export: rate, samples
per frame, GEN_SCALE, and per channel its number, name, label, description, units, scale
and offset), ``schema``, ``schema_version``,
``provenance`` (the stored record), ``streams`` (MCAP topic -> frames, rate_hz, names),
``datasets`` (HDF5 path -> shape, dtype, units), ``entities`` (rerun entity -> archetypes),
``calibration`` (ATI serial, matrix etc.) and ``details`` (format-specific extras: header keys,
validation result).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from core.errors import BadInput
from ingest.detect import detect_format
from ingest.inspect_lab import (
    inspect_c3d,
    inspect_cal,
    inspect_force,
    inspect_qtm_3d,
    inspect_qtm_6d,
    inspect_qtm_analog,
    inspect_qtm_mat,
    inspect_session,
)
from ingest.inspect_outputs import inspect_hdf5, inspect_json, inspect_mcap, inspect_rrd
from ingest.qtm_mat import MAT_ERRORS

_READ_ERRORS: tuple[type[Exception], ...] = (*MAT_ERRORS, ArithmeticError, LookupError,
                                             UnicodeError, RuntimeError)
KEYS = ("path", "format", "frames", "rate_hz", "duration_s", "markers", "bodies", "channels",
        "missing_samples", "holes", "units", "events", "analog", "schema", "schema_version",
        "provenance", "streams", "datasets", "entities", "calibration", "details")
INSPECT: dict[str, Callable[[Path], dict[str, Any]]] = {
    "qtm_tsv_3d": inspect_qtm_3d, "qtm_tsv_6d": inspect_qtm_6d, "c3d": inspect_c3d,
    "qtm_tsv_analog": inspect_qtm_analog,
    "qtm_mat": inspect_qtm_mat, "force_csv": inspect_force, "force_mat": inspect_force,
    "force_parquet": inspect_force, "force_ati_daq": inspect_force,
    "force_ati_netft": inspect_force, "qtm_tsv_force": inspect_force, "ati_cal": inspect_cal,
    "mcap": inspect_mcap,
    "hdf5": inspect_hdf5, "json": inspect_json, "rrd": inspect_rrd,
    "session_toml": inspect_session,
}


def run_inspect(inputs: str | Path, out: None = None, params: None = None,
                rrd: None = None) -> dict[str, Any]:
    """The summary of the file ``inputs`` (see the module doc for its keys); unknown formats
    are bad input. Inspect writes nothing and has no settings: ``out``, ``params`` and
    ``rrd`` are there for the runners' one signature and stay None."""
    if not (out is None and params is None and rrd is None):
        raise ValueError("inspect writes nothing and has no settings: out, params, rrd are None")
    path = Path(inputs)
    if not path.is_file():
        raise BadInput(path, "no such file")
    fmt = "file"
    try:
        fmt = "rrd" if _is_rrd(path) else _detect(path)
        summary: dict[str, Any] = dict.fromkeys(KEYS)
        summary.update(path=str(path), format=fmt, details={})
        summary.update(INSPECT[fmt](path))
    except _READ_ERRORS as e:        # a reader's library failing on a damaged file
        raise BadInput(path, f"cannot read it as {fmt} ({type(e).__name__}: {e})") from None
    return summary


def _detect(path: Path) -> str:
    fmt = detect_format(path)
    if fmt not in INSPECT:
        raise BadInput(path, f"no summary for format {fmt!r}")
    return fmt


def _is_rrd(path: Path) -> bool:
    with open(path, "rb") as f:
        return f.read(3) == b"RRF"

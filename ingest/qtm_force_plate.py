"""QTM force-plate exports (``<trial>_f_1.tsv``): the plate is the force sensor.

A header of ``KEY <tab> value`` lines (``NO_OF_SAMPLES``, ``FREQUENCY``, ``FORCE_PLATE_TYPE``,
``FORCE_PLATE_NAME``, the corners, ``FORCE_PLATE_LENGTH`` ...), then the column line
``SAMPLE TIME Force_X Force_Y Force_Z Moment_X Moment_Y Moment_Z COP_X COP_Y COP_Z`` and the
samples (older exports: no column line and no SAMPLE and TIME, the nine values only). QTM
writes forces in N, moments in N m and the centre of pressure in mm, in the plate's own frame
(the export's DESCRIPTION says which); the samples share the mocap's clock (time 0 at the
first frame of the capture), as the analog board's do. The plate's name, type and corners (QTM's
corners 1 to 4, ``FORCE_PLATE_CORNER_POSX_POSY_X`` ..., lab mm) go with the samples where the
header states them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from core.errors import BadInput
from core.holes import counted_numbers, grid_numbers
from ingest.csv_dialect import read_text_table, sniff_dialect
from ingest.log_table import LogTable

COLUMNS = ("Force_X", "Force_Y", "Force_Z", "Moment_X", "Moment_Y", "Moment_Z",
           "COP_X", "COP_Y", "COP_Z")
UNITS = dict(zip(COLUMNS, ("N",) * 3 + ("N*m",) * 3 + ("mm",) * 3, strict=True))
WRENCH = list(COLUMNS[:6])
CORNERS = ("POSX_POSY", "NEGX_POSY", "NEGX_NEGY", "POSX_NEGY")   # QTM's corners 1 to 4
TIME_PRINT_S = 5e-6    # QTM writes a plate's TIME with 5 decimals


def _exact_time(path: str | Path, time: np.ndarray, rate: float,
                sample: np.ndarray | None) -> np.ndarray:
    """TIME as QTM writes it (5 decimals: 1200 Hz is not exact) recomputed from FREQUENCY and
    the samples' numbers (SAMPLE, else where TIME puts them on FREQUENCY's grid): a hole of
    lost samples skips numbers and stays a jump. TIME more than half a sample off its
    number's time contradicts the header."""
    if len(time) == 0:
        return time
    numbers = counted_numbers(sample, path) if sample is not None else \
        grid_numbers(time, rate, path, "TIME", TIME_PRINT_S)
    exact = time[0] + numbers / rate
    off = float(np.abs(time - exact).max())
    if not off <= 0.5 / rate:
        raise BadInput(path, f"TIME departs from FREQUENCY {rate:g} Hz by up to "
                             f"{off * 1e3:.3f} ms: the header contradicts the data")
    return exact


def corner_keys() -> list[str]:
    """The header keys of the plate's corners, in QTM's order: corner 1 x, y, z, corner 2 ..."""
    return [f"FORCE_PLATE_CORNER_{c}_{a}" for c in CORNERS for a in "XYZ"]


def plate_corners(metadata: dict[str, str]) -> list[list[float]] | None:
    """The plate's four corners (lab, mm) from an export's header keys; None unless it gives
    all twelve numbers."""
    try:
        xyz = [float(metadata[k]) for k in corner_keys()]
    except (KeyError, ValueError):
        return None
    return [xyz[i:i + 3] for i in range(0, 12, 3)]


def export_plate_name(path: str | Path) -> str | None:
    """The plate an export is of (``FORCE_PLATE_NAME``), from its header alone."""
    return sniff_dialect(path, delimiter="\t", decimal=".").metadata.get("FORCE_PLATE_NAME")


def looks_like_force_plate(head: str) -> bool:
    """A QTM TSV header with FORCE_PLATE_* keys."""
    return "\nFORCE_PLATE_" in head.replace("\r", "") and "\t" in head


def read_force_plate(path: str | Path) -> LogTable:
    """The plate's force, moment and centre of pressure, timed by TIME or FREQUENCY."""
    d = sniff_dialect(path, delimiter="\t", decimal=".")
    t = read_text_table(path, d, "qtm_tsv_force")
    rate = d.metadata.get("FREQUENCY")
    try:
        t.rate_hz = None if rate is None else float(rate)
    except ValueError:
        raise BadInput(path, f"FREQUENCY {rate!r} is not a number") from None
    if d.header_line is None:
        if len(t.columns) != len(COLUMNS):
            raise BadInput(path, f"rows have {len(t.columns)} fields; a force-plate export "
                                 f"without a column line has the {len(COLUMNS)} of "
                                 f"{', '.join(COLUMNS)}")
        t.columns = dict(zip(COLUMNS, t.columns.values(), strict=True))
        t.time = None
    else:
        t.columns = {k.strip(): v for k, v in t.columns.items()}
        t.time = "TIME" if "TIME" in t.columns else None
        if t.time is not None and t.rate_hz:
            sample = t.columns.get("SAMPLE")
            t.columns["TIME"] = _exact_time(path, np.asarray(t.columns["TIME"], float),
                                            t.rate_hz, None if sample is None else
                                            np.asarray(sample, float))
    t.time_unit = "s"
    t.units = {k: u for k, u in UNITS.items() if k in t.columns}
    t.details.update(plate=d.metadata.get("FORCE_PLATE_NAME"),
                     plate_type=d.metadata.get("FORCE_PLATE_TYPE"),
                     plate_corners_mm=plate_corners(d.metadata),
                     description=d.metadata.get("DESCRIPTION"), clock="mocap")
    return t

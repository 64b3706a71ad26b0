"""What every force-log reader hands the force-log stage: named 1-D columns and what the file
says about them.

A layout reader (plain or dialect CSV, ATI's DAQ F/T and Net F/T logs, QTM force-plate
exports, MAT arrays and structs, Parquet) turns its file into a :class:`LogTable`: the columns
in file order, the units the file states per column, the column the layout knows to be time
(or the rate it states where it has no time column), and how to name a row in a message.
:mod:`ingest.force_log` then picks the time and the channels that session.toml names, and
converts them; ``numbers`` is the one check that a column holds numbers.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from core.errors import BadInput

Where = Callable[[int], str]      # row index -> "line 12" / "row 11"


def row_where(i: int) -> str:
    """A MAT or Parquet row, 1-based."""
    return f"row {i + 1}"


@dataclass
class LogTable:
    """A force log's columns as the file has them, before any unit is applied."""

    format: str                              # detect name: force_csv, force_mat, ...
    columns: dict[str, Any]                  # name -> 1-D values (ndarray or pandas Series)
    where: Where = row_where
    units: dict[str, str] = field(default_factory=dict)    # units the file states, per column
    time: str | None = None                  # the column the layout knows to be time
    time_alias: str | None = None            # the file's own name for it (a model's tout),
                                             # which session.toml's time_column may give
    time_unit: str | None = None             # the unit the file states for it
    rate_hz: float | None = None             # the rate the file states (no time column)
    details: dict[str, Any] = field(default_factory=dict)  # what inspect shows

    @property
    def names(self) -> list[str]:
        return list(self.columns)


def require(path: str | Path, available: list[str], wanted: list[str], what: str = "column(s)",
            hint: str = "") -> None:
    """Every wanted name is available, else one line listing what the file has."""
    absent = [w for w in wanted if w not in available]
    if absent:
        shown = ", ".join(available[:20]) + (" ..." if len(available) > 20 else "")
        raise BadInput(path, f"{what} not in file: {', '.join(absent)} "
                             f"(the file has: {shown or 'nothing readable'}){hint}")


def numbers(path: str | Path, name: str, values: Any, where: Where) -> np.ndarray:
    """A column as float64 (int64 kept for exact times); text or NaN -> BadInput with the row."""
    s = pd.Series(values) if not isinstance(values, pd.Series) else values
    if s.dtype.kind in "iu":
        return s.to_numpy(dtype=np.int64)
    if s.dtype.kind not in "fb":
        num = pd.to_numeric(s, errors="coerce")
        bad = np.flatnonzero(num.isna().to_numpy() & s.notna().to_numpy())
        if bad.size:
            i = int(bad[0])
            raise BadInput(path, f"{s.iloc[i]!r} in column {name} is not a number",
                           where=where(i))
        s = num
    out = s.to_numpy(dtype=np.float64, na_value=np.nan)
    bad = np.flatnonzero(~np.isfinite(out))
    if bad.size:
        i = int(bad[0])
        raise BadInput(path, f"column {name} has no value (or an infinite one)", where=where(i))
    return out


def clock_ns(values: Any) -> np.ndarray | None:
    """Dates and clock times ("11/26/2026 9:00:02.500 AM", ISO 8601) as int64 ns since the
    epoch, or None where the column is numbers (or not dates)."""
    s = pd.Series(values) if not isinstance(values, pd.Series) else values
    if s.dtype.kind in "iufb" or not len(s):
        return None
    text = s.astype(str).str.strip()
    if pd.to_numeric(text.iloc[:1], errors="coerce").notna().all():
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            parsed = pd.to_datetime(text, format="mixed")
    except (ValueError, TypeError, OverflowError):
        return None
    return parsed.to_numpy(dtype="datetime64[ns]").astype(np.int64)

"""Force-sensor logs (the Speedgoat target's Nano17 record): CSV, MAT v7 / v7.3, or Parquet.

Every format comes down to named 1-D columns: a time column, the six channels (gauge volts or a
calibrated wrench) and optionally a trigger. MAT files hold one variable per column, or one 2-D
matrix plus a ``columns`` / ``names`` cell array of strings. Values are checked (numbers, no
NaN, time strictly increasing), time becomes int64 ns and channels SI units.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import scipy.io

from core.errors import BadInput
from core.series import ForceSeries, time_to_ns
from core.text import attr_text
from core.units import TIME_UNITS, channel_units, unit_to_si
from ingest.qtm_mat import MAT_ERRORS, mat73_text
from ingest.sniff import check_last_line, sniff

_NAME_VARS = ("columns", "names", "column_names")
_MAT_SKIP = ("#refs#", "#subsystem#")
_READ_ERRORS = (*MAT_ERRORS, pa.ArrowException)    # any reader's failure on a damaged file
_PANDAS_LINE = re.compile(r"in line (\d+)")

Where = Callable[[int], str]      # row index -> "line 12" / "row 11"


# ---------------------------------------------------------------------------- columns


def force_log_columns(path: str | Path) -> list[str]:
    """The column names a force log offers (CSV header, MAT variables, Parquet schema)."""
    kind = _kind(path)
    try:
        if kind == "csv":
            return _csv_header(path)[0]
        if kind == "parquet":
            return list(pq.read_schema(path).names)
        return list(_mat_columns(path, kind, None))
    except _READ_ERRORS as e:
        raise BadInput(path, f"cannot read force log ({e})") from None


def _kind(path: str | Path) -> str:
    kind = sniff(path)
    if kind in ("mat5", "mat73", "parquet"):
        return kind
    if kind == "text":
        return "csv"
    raise BadInput(path, f"not a force log (CSV, MAT or Parquet); found {kind}")


# ---------------------------------------------------------------------------- CSV


def _csv_header(path: str | Path) -> tuple[list[str], str]:
    """Column names of the first line and the separator (tab when the line has one, else ,)."""
    with open(path, encoding="utf-8-sig", errors="replace") as f:
        first = f.readline().rstrip("\r\n")
    sep = "\t" if "\t" in first else ","
    names = [c.strip().strip('"') for c in first.split(sep)]
    dups = sorted({n for n in names if names.count(n) > 1})
    if dups:
        raise BadInput(path, f"duplicate column name(s) in the header: {', '.join(dups)}",
                       where="line 1")
    return names, sep


def _csv_columns(path: str | Path, wanted: list[str]) -> tuple[dict[str, pd.Series], Where]:
    """The wanted columns of a CSV log. Every row must have the header's number of fields
    (pandas' C parser checks; a trailing separator on every row is allowed)."""
    header, sep = _csv_header(path)
    _require(path, header, wanted)
    try:
        with warnings.catch_warnings():
            # "Length of header ... does not match length of data": an extra first-row field
            warnings.simplefilter("error", pd.errors.ParserWarning)
            df = pd.read_csv(path, sep=sep, header=0, index_col=False, engine="c",
                             skipinitialspace=True, encoding="utf-8-sig")
    except pd.errors.ParserWarning:
        raise BadInput(path, f"row has more fields than the {len(header)} of the header",
                       where="line 2") from None
    except (ValueError, pd.errors.ParserError, UnicodeDecodeError) as e:
        line = _PANDAS_LINE.search(str(e))
        raise BadInput(path, f"cannot parse CSV ({str(e).strip()})",
                       where=f"line {line.group(1)}" if line else None) from None
    if df.shape[1] != len(header):
        raise BadInput(path, f"the header names {len(header)} columns, pandas found "
                             f"{df.shape[1]} (quoted separators?)", where="line 1")
    with open(path, encoding="utf-8-sig", errors="replace") as f:
        f.readline()
        second = f.readline().rstrip("\r\n").split(sep)
    check_last_line(path, sep, len(header), second, len(df) + 1)
    return {c: df.iloc[:, header.index(c)] for c in wanted}, lambda i: f"line {i + 2}"


# ---------------------------------------------------------------------------- MAT


def _mat_variables(path: str | Path, kind: str) -> dict[str, Any]:
    """Every variable of a MAT file: numeric arrays in MATLAB's shape, cellstr as lists."""
    if kind == "mat5":
        raw = scipy.io.loadmat(path, squeeze_me=False)
        out: dict[str, Any] = {}
        for k, v in raw.items():
            if k.startswith("__") or not isinstance(v, np.ndarray) or v.dtype.names:
                continue                                 # MATLAB's own keys, structs
            if v.dtype == object:                    # a cell array of strings
                out[k] = [str(np.ravel(x)[0]) if np.size(x) else "" for x in v.ravel(order="F")]
            elif v.dtype.kind in "US":
                out[k] = [str(s).strip() for s in np.ravel(v)]
            else:
                out[k] = v
        return out
    out = {}
    with h5py.File(path, "r") as f:
        for k in f:
            ds = f[k]
            if k in _MAT_SKIP or not isinstance(ds, h5py.Dataset):
                continue
            cls = attr_text(ds.attrs.get("MATLAB_class", b"double"))
            if cls == "cell":
                out[k] = [mat73_text(f[r]) for r in np.asarray(ds[()]).ravel(order="F")]
            elif cls == "char":
                out[k] = [mat73_text(ds)]
            elif ds.attrs.get("MATLAB_empty", 0):
                out[k] = np.zeros((0, 0))
            else:
                out[k] = np.asarray(ds[()]).T           # MATLAB stores dimensions reversed
    return out


def _mat_columns(path: str | Path, kind: str, wanted: list[str] | None) -> dict[str, np.ndarray]:
    """Named 1-D columns of a MAT force log (all of them when ``wanted`` is None)."""
    variables = _mat_variables(path, kind)
    vectors = {k: np.ravel(v) for k, v in variables.items()
               if isinstance(v, np.ndarray) and v.ndim <= 2 and min(v.shape, default=0) == 1}
    if wanted is not None and all(w in vectors for w in wanted):
        return {w: vectors[w] for w in wanted}
    names_var = next((k for k in _NAME_VARS if isinstance(variables.get(k), list)), None)
    if names_var is None:
        if wanted is not None:
            _require(path, list(vectors), wanted)
        return vectors
    names = [s.strip() for s in variables[names_var]]
    matrices = [v for v in variables.values() if isinstance(v, np.ndarray) and v.ndim == 2
                and len(names) in v.shape and min(v.shape) > 1]
    if len(matrices) != 1:
        raise BadInput(path, f"{names_var} names {len(names)} columns but there is "
                             f"{'no' if not matrices else 'more than one'} matrix with that "
                             "many columns")
    m = matrices[0]
    m = m if m.shape[1] == len(names) else m.T
    columns = {n: m[:, i] for i, n in enumerate(names)}
    if wanted is not None:
        _require(path, names, wanted)
    return columns


# ---------------------------------------------------------------------------- checks


def _require(path: str | Path, available: list[str], wanted: list[str]) -> None:
    absent = [w for w in wanted if w not in available]
    if absent:
        raise BadInput(path, f"column(s) not in file: {', '.join(absent)} "
                             f"(the file has: {', '.join(available)})")


def _numbers(path: str | Path, name: str, values: Any, where: Where) -> np.ndarray:
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


def _time_ns(path: str | Path, t: np.ndarray, unit: str, where: Where) -> np.ndarray:
    ns = time_to_ns(t, path, unit, where)
    bad = np.flatnonzero(np.diff(ns) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise BadInput(path, f"time is not increasing ({t[i]} after {t[i - 1]} {unit})",
                       where=where(i))
    return ns


def _units(path: str | Path, units: str | list[str] | None, kind: str,
           n: int) -> tuple[np.ndarray, list[str], list[str]]:
    """Per-channel SI factors, SI unit names and the units as given."""
    try:
        given = channel_units(units, kind, n)
    except ValueError as e:
        raise BadInput(path, str(e)) from None
    factors, si = zip(*(unit_to_si(u) for u in given), strict=True)
    return np.array(factors), list(si), given


# ---------------------------------------------------------------------------- reader


def read_force_log(
    path: str | Path,
    time_column: str,
    channels: list[str],
    time_unit: str = "s",
    units: str | list[str] | None = None,
    kind: str = "gauge",
    trigger_column: str | None = None,
) -> ForceSeries:
    """Read a force log (CSV, MAT v7/v7.3, Parquet) into a ``ForceSeries`` in SI units.

    ``kind`` is "gauge" (volts, calibrated later with an ATI matrix) or "wrench" (Fx..Tz);
    ``units`` is one unit for all channels or one per channel (default V, or N and N*m).
    """
    if time_unit not in TIME_UNITS:
        raise BadInput(path, f"time_unit must be one of {', '.join(TIME_UNITS)}, "
                             f"got {time_unit!r}")
    if not channels or len(set(channels)) != len(channels):
        raise BadInput(path, "channels must be a non-empty list of distinct column names")
    factors, si_units, given = _units(path, units, kind, len(channels))
    wanted = [time_column, *channels] + ([trigger_column] if trigger_column else [])
    fmt = _kind(path)
    try:
        if fmt == "csv":
            cols, where = _csv_columns(path, wanted)
        elif fmt == "parquet":
            schema = pq.read_schema(path).names
            _require(path, schema, wanted)
            table = pq.read_table(path, columns=wanted)
            cols = {c: table.column(c).to_pandas() for c in wanted}
            where = _row
        else:
            cols, where = _mat_columns(path, fmt, wanted), _row
    except _READ_ERRORS as e:
        raise BadInput(path, f"cannot read force log ({e})") from None
    lengths = {c: len(v) for c, v in cols.items()}
    if len(set(lengths.values())) != 1:
        raise BadInput(path, f"columns have different lengths: {lengths}")
    n = lengths[time_column]
    if n < 2:
        raise BadInput(path, f"force log has {n} sample(s); need at least 2")
    t = _numbers(path, time_column, cols[time_column], where)
    time_ns = _time_ns(path, t, time_unit, where)
    values = np.empty((n, len(channels)))
    for i, c in enumerate(channels):
        values[:, i] = _numbers(path, c, cols[c], where) * factors[i]
    trigger = None
    if trigger_column:
        trigger = _numbers(path, trigger_column, cols[trigger_column], where).astype(np.float64)
    rate = 1e9 / float(np.median(np.diff(time_ns)))
    meta = {"format": {"csv": "force_csv", "parquet": "force_parquet"}.get(fmt, "force_mat"),
            "time_column": time_column, "time_unit": time_unit, "units_in_file": given}
    return ForceSeries(source=str(path), time_ns=time_ns, channels=list(channels),
                       values=values, units=si_units, kind=kind, rate_hz=rate, trigger=trigger,
                       meta=meta)


def _row(i: int) -> str:
    return f"row {i + 1}"

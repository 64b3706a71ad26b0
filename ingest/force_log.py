"""Force-sensor logs (the Speedgoat target's Nano17 record, or any rig's): every layout a lab
is likely to hand over, read into a ``ForceSeries`` in SI units.

The container decides the reader, each giving a :class:`~ingest.log_table.LogTable`: Parquet;
MAT v7 / v7.3 (:mod:`ingest.mat_log`: named columns, Simulink arrays and structs); text
(:mod:`ingest.qtm_force_plate` for a QTM force-plate export, :mod:`ingest.ati_csv` for ATI's
DAQ F/T and Net F/T logs, else :mod:`ingest.csv_dialect` in any common dialect). Then the
time (the named column, the layout's own, or the rate where the log has none) and the channels
(by name, or by number: 1 is the first column that is not time) are picked and checked
(numbers, no NaN, time strictly increasing), time becomes int64 ns and channels SI units
(:mod:`ingest.channel_scale`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from core.errors import BadInput
from core.series import SHARED_CLOCK, ForceSeries, frame_times_ns, time_to_ns
from core.units import TIME_UNITS, time_unit_in_name
from ingest.ati_csv import is_daq_ft, is_netft, read_daq_ft, read_netft
from ingest.channel_scale import to_si
from ingest.csv_dialect import read_text_table, sniff_dialect
from ingest.log_table import LogTable, Where, clock_ns, numbers, require, row_where
from ingest.mat_log import read_mat_table
from ingest.qtm_force_plate import looks_like_force_plate, read_force_plate
from ingest.qtm_mat import MAT_ERRORS
from ingest.sniff import head_text, read_head, sniff

_READ_ERRORS = (*MAT_ERRORS, RuntimeError, pa.ArrowException)   # a damaged file's failures
_RATE_TOLERANCE = 0.01          # a stated rate and the time column's may differ this much
TEXT_FORMATS = ("force_csv", "force_ati_daq", "force_ati_netft", "qtm_tsv_force")
# what of a layout's details the series keeps: a MAT or text layout, a force plate's identity
KEPT_DETAILS = ("layout", "variable", "dialect", "plate", "plate_type", "plate_corners_mm")


# ---------------------------------------------------------------------------- layouts


def _container(path: str | Path) -> str:
    kind = sniff(path)
    if kind in ("mat4", "mat5", "mat73", "parquet", "text"):
        return kind
    raise BadInput(path, f"not a force log (CSV, MAT or Parquet); found {kind}")


def text_log_format(path: str | Path, delimiter: str | None = None,
                    decimal: str | None = None, bare_rows: int = 2) -> str:
    """Which text log a file is (one of ``TEXT_FORMATS``); not a log -> BadInput. A file
    without a column line must show ``bare_rows`` rows of numbers (detection by content alone
    asks for more than a session.toml that names the file)."""
    if looks_like_force_plate(head_text(read_head(path)) or ""):
        return "qtm_tsv_force"
    d = sniff_dialect(path, delimiter, decimal)
    if d.header_line is None and d.data_rows < bare_rows:
        raise BadInput(path, f"{d.data_rows} rows of numbers without a column line: too few "
                             "to call it a log")
    return "force_ati_netft" if is_netft(d) else "force_ati_daq" if is_daq_ft(d) \
        else "force_csv"


def read_log_table(path: str | Path, variable: str | None = None,
                   delimiter: str | None = None, decimal: str | None = None,
                   wanted: list[str] | None = None) -> LogTable:
    """The columns of a force log as the file has them (see the module doc)."""
    kind = _container(path)
    try:
        if kind == "parquet":
            table = pq.read_table(path)
            return LogTable(format="force_parquet", where=row_where,
                            columns={c: table.column(c).to_pandas()
                                     for c in table.column_names})
        if kind in ("mat4", "mat5", "mat73"):
            return read_mat_table(path, kind, variable, wanted)
    except _READ_ERRORS as e:
        raise BadInput(path, f"cannot read force log ({e})") from None
    if variable is not None:
        raise BadInput(path, "force.variable is for MAT files; this is a text log")
    fmt = text_log_format(path, delimiter, decimal)
    if fmt == "qtm_tsv_force":
        return read_force_plate(path)
    d = sniff_dialect(path, delimiter, decimal)
    if fmt == "force_ati_netft":
        return read_netft(path, d)
    if fmt == "force_ati_daq":
        return read_daq_ft(path, d)
    return read_text_table(path, d)


def force_log_columns(path: str | Path) -> list[str]:
    """The column names a force log offers."""
    return read_log_table(path).names


# ---------------------------------------------------------------------------- picking


def _pick_time(path: str | Path, t: LogTable, time_column: str | None,
               rate_hz: float | None) -> str | None:
    """The time column's name (the named one, or the layout's own for the default name "time"
    or the file's own name for it, such as a model's ``tout``), or None for a log timed by
    its rate."""
    if time_column is not None and time_column in t.columns:
        return time_column
    if time_column is not None and time_column == t.time_alias and t.time is not None:
        return t.time
    if time_column in (None, "time"):
        if t.time is not None:
            return t.time
        if rate_hz is not None or t.rate_hz is not None:
            return None
    require(path, t.names, [time_column or "time"], "time column",
            hint="; name it with force.time_column, or give force.rate_hz for a log without "
                 "one")
    return None


def _pick(path: str | Path, t: LogTable, wanted: Sequence[str | int], time: str | None,
          what: str) -> list[str]:
    """Column names for channels given by name or number (1 = the first non-time column)."""
    signals = [c for c in t.names if c != time]
    out = []
    for w in wanted:
        if isinstance(w, int):
            if not 1 <= w <= len(signals):
                raise BadInput(path, f"{what}: channel number {w} is not in the file "
                                     f"(channels 1 to {len(signals)}, time apart)")
            out.append(signals[w - 1])
        else:
            out.append(w)
    require(path, t.names, [w for w in out if isinstance(w, str)])
    return out


def _time_ns(path: str | Path, t: np.ndarray, unit: str, where: Where) -> np.ndarray:
    ns = time_to_ns(t, path, unit, where)
    bad = np.flatnonzero(np.diff(ns) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise BadInput(path, f"time is not increasing ({t[i]} after {t[i - 1]} {unit})",
                       where=where(i))
    return ns


def _rate_time(path: str | Path, t: LogTable, n: int, rate_hz: float | None) -> np.ndarray:
    if rate_hz is not None and t.rate_hz is not None and \
            abs(rate_hz - t.rate_hz) > _RATE_TOLERANCE * t.rate_hz:
        raise BadInput(path, f"force.rate_hz is {rate_hz:g} Hz but the file states "
                             f"{t.rate_hz:g} Hz")
    rate = rate_hz if rate_hz is not None else t.rate_hz
    if rate is None:              # _pick_time wants a time column where no rate is known
        raise BadInput(path, "the log has neither a time column nor a rate (force.rate_hz)")
    return frame_times_ns(n, float(rate), path, "the log's rate")


# ---------------------------------------------------------------------------- reader


def read_force_log(
    path: str | Path,
    time_column: str | None,
    channels: Sequence[str | int],
    time_unit: str | None = None,
    units: str | list[str] | None = None,
    kind: str = "gauge",
    trigger_column: str | int | None = None,
    *,
    variable: str | None = None,
    delimiter: str | None = None,
    decimal: str | None = None,
    rate_hz: float | None = None,
    scale: list[float] | None = None,
    offset: list[float] | None = None,
    table: LogTable | None = None,
) -> ForceSeries:
    """Read a force log into a ``ForceSeries`` in SI units.

    ``kind`` is "gauge" (volts, calibrated later with an ATI matrix) or "wrench" (Fx..Tz).
    ``time_unit`` and ``units`` are None where session.toml states none: the file's own (a
    name such as ``time (ms)``, ``Force X (N)``), else s and the kind's default units.
    ``variable`` picks a MAT variable or struct field, ``delimiter``/``decimal`` a text
    dialect, ``rate_hz`` times a log without a time column, ``scale``/``offset`` turn volts
    into N and N m (:mod:`ingest.channel_scale`). ``table``: the log's columns as read
    elsewhere (a force plate's samples off QTM's real-time stream, ``path`` then naming the
    server), picked and converted exactly as the file's would be.
    """
    if time_unit is not None and time_unit not in TIME_UNITS:
        raise BadInput(path, f"time_unit must be one of {', '.join(TIME_UNITS)}, "
                             f"got {time_unit!r}")
    if not channels or len(set(channels)) != len(channels):
        raise BadInput(path, "channels must be a non-empty list of distinct column names")
    if kind not in ("gauge", "wrench"):
        raise BadInput(path, f"kind must be one of gauge, wrench, got {kind!r}")
    t = table if table is not None else read_log_table(
        path, variable, delimiter, decimal,
        wanted=[c for c in [time_column, *channels, trigger_column] if isinstance(c, str)])
    time = _pick_time(path, t, time_column, rate_hz)
    names = _pick(path, t, channels, time, "force.channels")
    trigger = _pick(path, t, [trigger_column], time, "force.trigger_column")[0] \
        if trigger_column is not None else None
    used = ([time] if time else []) + names + ([trigger] if trigger else [])
    lengths = {c: len(t.columns[c]) for c in used}
    if len(set(lengths.values())) != 1:
        raise BadInput(path, f"columns have different lengths: {lengths}")
    n = lengths[used[0]]
    if n < 2:
        raise BadInput(path, f"force log has {n} sample(s); need at least 2")
    if time is not None:
        unit = _time_unit(path, t, time, time_unit)
        clock = clock_ns(t.columns[time])
        if clock is not None:                  # dates and clock times, not numbers
            time_ns, unit = _time_ns(path, clock, "ns", t.where), "ns"
        else:
            time_ns = _time_ns(path, numbers(path, time, t.columns[time], t.where), unit,
                               t.where)
        _check_rate(path, time_ns, rate_hz)
    else:
        unit = None
        time_ns = _rate_time(path, t, n, rate_hz)
    raw = np.column_stack([numbers(path, c, t.columns[c], t.where) for c in names])
    values, si_units, info = to_si(path, raw.astype(np.float64), names,
                                   [t.units.get(c, "") for c in names], kind, units,
                                   scale, offset)
    trig = numbers(path, trigger, t.columns[trigger], t.where).astype(np.float64) \
        if trigger else None
    rate = 1e9 / float(np.median(np.diff(time_ns)))
    meta = {"format": t.format, "time_column": time, "time_unit": unit,
            "trigger_column": trigger,
            "timed_by": "column" if time else "rate", **info,
            **({"clock": SHARED_CLOCK} if t.details.get("clock") == "mocap" else {}),
            **{k: v for k, v in t.details.items() if k in KEPT_DETAILS}}
    return ForceSeries(source=str(path), time_ns=time_ns, channels=names, values=values,
                       units=si_units, kind=kind, rate_hz=rate, trigger=trig, meta=meta)


def _time_unit(path: str | Path, t: LogTable, time: str, stated: str | None) -> str:
    """The layout's own time unit; else session.toml's, which must agree with the file's (a
    units line, the column's name) where it states one; else the file's; else s."""
    if time == t.time and t.time_unit:
        return t.time_unit
    file_unit = t.units.get(time) if t.units.get(time) in TIME_UNITS else \
        time_unit_in_name(time)
    if stated and file_unit and stated != file_unit:
        raise BadInput(path, f"force.time_unit is {stated!r}, but the file states {file_unit!r} "
                             f"for its time column {time!r}")
    return stated or file_unit or "s"


def _check_rate(path: str | Path, time_ns: np.ndarray, rate_hz: float | None) -> None:
    """A rate session.toml states must be the time column's."""
    if rate_hz is None:
        return
    rate = 1e9 / float(np.median(np.diff(time_ns)))
    if abs(rate - rate_hz) > _RATE_TOLERANCE * rate_hz:
        raise BadInput(path, f"force.rate_hz is {rate_hz:g} Hz but the time column gives "
                             f"{rate:.6g} Hz")

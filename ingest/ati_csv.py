"""ATI's own CSV logs: the DAQ F/T demo's and the Net F/T's.

- **DAQ F/T** (ATI's DAQ F/T .NET demo, "Data Collection"): every field quoted, the culture's
  list separator (``;`` under a European locale, with decimal commas); the column line names
  ``"Force X (N)"`` .. ``"Torque Z (N-mm)"`` (units in the names) or ``"G0"`` .. ``"G5"``
  (and ``"Therm"``), then ``"Frequency = 1000"``, ``"Averaging Level = 1"``, ``"F/T Serial
  Number = ..."``, ``"Time Started = ..."``; no time column (the rate is Frequency over the
  averaging level); optionally a first line saying how long it paused before saving.
- **Net F/T** (ATI's Net F/T demo, ``NetFTSampleGUI``, "collect to file"): a preamble of
  ``key: value`` (or ``key, value``) lines (start time, RDT sample rate, force and torque
  units, counts per unit force and torque), then ``Status (hex), RDT Sequence, F/T Sequence,
  Fx, Fy, Fz, Tx, Ty, Tz, Time``, every field quoted; the wrench in units (demo 1.1) or in
  raw counts (whole numbers: divided here by the counts per unit), the time as a date and a
  clock time to the second (so the RDT sequence at the RDT rate times the samples).

Both are read by :mod:`ingest.csv_dialect`; this module reads what their metadata means.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from core.errors import BadInput
from core.units import unit_to_si
from ingest.csv_dialect import Dialect, read_text_table
from ingest.log_table import LogTable, clock_ns, numbers

NETFT_MARKS = ("rdt sequence", "f/t sequence", "status (hex)")
_RATE_KEYS = re.compile(r"^(frequency|sample rate|sampling rate|sample frequency|"
                        r"sampling frequency|rate)(\s*\(hz\))?$", re.IGNORECASE)
_AVERAGING = re.compile(r"^averaging( level)?$", re.IGNORECASE)
_RDT_RATE = re.compile(r"^rdt (sample )?rate", re.IGNORECASE)
_DAQ_NAME = re.compile(r"^(force|torque) [xyz]\b", re.IGNORECASE)
_FORCES, _TORQUES = ("Fx", "Fy", "Fz"), ("Tx", "Ty", "Tz")


def is_netft(d: Dialect) -> bool:
    return any(h.strip().lower() in NETFT_MARKS for h in d.header)


def is_daq_ft(d: Dialect) -> bool:
    return _rate(d.metadata, _RATE_KEYS) is not None or any(_DAQ_NAME.match(h)
                                                            for h in d.header)


def _rate(meta: dict[str, str], key: re.Pattern[str]) -> float | None:
    for k, v in meta.items():
        if key.match(k.strip()):
            m = re.match(r"\s*([0-9.]+)", v.replace(",", "."))
            if m:
                return float(m.group(1))
    return None


def _meta(meta: dict[str, str], words: str) -> str | None:
    for k, v in meta.items():
        if k.strip().lower() == words:
            return v.strip()
    return None


def read_daq_ft(path: str | Path, d: Dialect) -> LogTable:
    """A DAQ F/T log: the columns, each name's unit, the rate: ``Frequency`` over the
    ``Averaging Level`` (each record averages that many new samples, as the demo says)."""
    t = read_text_table(path, d, "force_ati_daq")
    rate = _rate(d.metadata, _RATE_KEYS)
    averaging = _rate(d.metadata, _AVERAGING)
    if rate is not None and not rate > 0 or averaging is not None and not averaging >= 1:
        raise BadInput(path, f"the header's Frequency ({rate}) or Averaging Level "
                             f"({averaging}) is not a rate")
    t.rate_hz = None if rate is None else rate / (averaging or 1.0)
    return t


def read_netft(path: str | Path, d: Dialect) -> LogTable:
    """A Net F/T log: Fx..Tz in the preamble's units (divided by its counts per unit where the
    file holds raw counts: whole numbers; ATI's demo 1.1 writes them already divided), time
    from the Time column or, where its clock time repeats, the RDT sequence at the RDT rate."""
    t = read_text_table(path, d, "force_ati_netft")
    missing = [c for c in (*_FORCES, *_TORQUES) if c not in t.columns]
    if missing:
        raise BadInput(path, f"Net F/T log without column(s) {', '.join(missing)}")
    counts = all(pd.Series(t.columns[a]).dtype.kind in "iu" for a in (*_FORCES, *_TORQUES))
    for axes, what in ((_FORCES, "force"), (_TORQUES, "torque")):
        unit = _meta(d.metadata, f"{what} units")
        if unit is not None:
            try:
                unit_to_si(unit)
            except ValueError:
                raise BadInput(path, f"the preamble's {what} units {unit!r} are unknown") \
                    from None
        per_unit = _counts_per_unit(path, d.metadata, what) if counts else 1.0
        for a in axes:
            if per_unit != 1.0:
                t.columns[a] = numbers(path, a, t.columns[a], t.where) / per_unit
            if unit is not None:
                t.units[a] = unit
    t.details["values"] = "counts / counts per unit" if counts else "in the preamble's units"
    if "Time" in t.columns:
        t.columns["Time"] = _clock_times(path, t, _rate(d.metadata, _RDT_RATE))
        t.time, t.time_unit = "Time", "ns"
    return t


def _counts_per_unit(path: str | Path, meta: dict[str, str], what: str) -> float:
    """The preamble's counts per unit force (torque); 1 where it states none."""
    text = _meta(meta, f"counts per unit {what}")
    if text is None:
        return 1.0
    try:
        value = float(text.replace(",", "."))
    except ValueError:
        value = float("nan")
    if not (np.isfinite(value) and value > 0):
        raise BadInput(path, f"the preamble's counts per unit {what} is {text!r}, not a "
                             "number > 0")
    return value


def _clock_times(path: str | Path, t: LogTable, rdt_hz: float | None) -> np.ndarray:
    """The Time column as int64 ns: numbers (s) as they are; date and clock text parsed; where
    the clock repeats (ATI's demo writes whole seconds) and the RDT rate is known, the RDT
    sequence from the first clock time."""
    raw = t.columns["Time"]
    num = pd.to_numeric(raw, errors="coerce")
    if num.notna().all():
        return np.rint(num.to_numpy(dtype=np.float64) * 1e9).astype(np.int64)
    ns = clock_ns(raw)
    if ns is None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            parsed = pd.to_datetime(raw.astype(str).str.strip(), format="mixed",
                                    errors="coerce")
        bad = int(np.flatnonzero(parsed.isna().to_numpy() & num.isna().to_numpy())[0])
        what = f"Time {raw.iloc[bad]!r} is neither seconds nor a date and time" \
            if pd.notna(raw.iloc[bad]) else "the row has no Time (too few fields?)"
        raise BadInput(path, what, where=t.where(bad))
    if np.all(np.diff(ns) > 0) or rdt_hz is None or "RDT Sequence" not in t.columns:
        return ns
    seq = numbers(path, "RDT Sequence", t.columns["RDT Sequence"], t.where).astype(np.float64)
    t.details["time_from"] = f"RDT Sequence at {rdt_hz:g} Hz (the clock time repeats)"
    return ns[0] + np.rint((seq - seq[0]) * (1e9 / rdt_hz)).astype(np.int64)

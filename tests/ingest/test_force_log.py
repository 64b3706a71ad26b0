"""Force-log reader: the same log as CSV (comma, tab), MAT v7 / v7.3 (columns or a matrix with
names) and Parquet reads back identically; times, units and bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.io

from core.errors import BadInput
from ingest.force_log import force_log_columns, read_force_log
from ingest.qtm_mat import write_mat73

GAUGES = [f"G{i}" for i in range(6)]
N = 500


def _log() -> pd.DataFrame:
    rng = np.random.default_rng(11)
    df = pd.DataFrame(np.round(rng.normal(0, 2, (N, 6)), 6), columns=GAUGES)
    df.insert(0, "time", np.round(12.5 + np.arange(N) * 0.001, 6))
    df["trigger"] = (np.arange(N) % 100 == 0).astype(float)
    return df


def _write(df: pd.DataFrame, path: Path, how: str) -> Path:
    cols = {c: df[c].to_numpy() for c in df.columns}
    names = np.array(list(df.columns), dtype=object)
    if how == "csv":
        df.to_csv(path, index=False)
    elif how == "tsv":
        df.to_csv(path, index=False, sep="\t")
    elif how == "parquet":
        df.to_parquet(path)
    elif how == "mat7":
        scipy.io.savemat(path, cols)
    elif how == "mat7-matrix":
        scipy.io.savemat(path, {"data": df.to_numpy(), "columns": names})
    elif how == "mat73":
        write_mat73(path, {k: v[:, None] for k, v in cols.items()})     # MATLAB column vectors
    elif how == "mat73-matrix":
        write_mat73(path, {"log": df.to_numpy(), "names": list(df.columns)})
    return path


FORMATS = ["csv", "tsv", "parquet", "mat7", "mat7-matrix", "mat73", "mat73-matrix"]


@pytest.mark.parametrize("how", FORMATS)
def test_every_format_reads_the_same_log(tmp_path, how):
    df = _log()
    p = _write(df, tmp_path / f"force.{how}", how)
    s = read_force_log(p, "time", GAUGES, trigger_column="trigger")
    assert s.values == pytest.approx(df[GAUGES].to_numpy(), abs=0)
    assert s.time_ns[0] == 12_500_000_000 and s.time_ns[-1] == 12_500_000_000 + (N - 1) * 10**6
    assert s.rate_hz == pytest.approx(1000.0)
    assert s.units == ["V"] * 6 and s.kind == "gauge" and s.channels == GAUGES
    assert s.trigger is not None and s.trigger.sum() == 5
    assert set(force_log_columns(p)) >= {"time", *GAUGES, "trigger"}


def test_time_units_rounding_and_integer_times(tmp_path):
    df = pd.DataFrame({"t_ms": [0.0, 0.9999999999, 2.0000000001], "Fx": [1.0, 2, 3]})
    s = read_force_log(_write(df, tmp_path / "ms.csv", "csv"), "t_ms", ["Fx"], time_unit="ms",
                       units="N", kind="wrench")
    assert s.time_ns.tolist() == [0, 1_000_000, 2_000_000]             # rounded, not truncated
    big = 1_700_000_000_123_456_789
    df = pd.DataFrame({"t": [big, big + 1_000_001, big + 2_000_000], "Fx": [1.0, 2, 3]})
    s = read_force_log(_write(df, tmp_path / "ns.parquet", "parquet"), "t", ["Fx"],
                       time_unit="ns", units="N", kind="wrench")
    assert s.time_ns.tolist() == [big, big + 1_000_001, big + 2_000_000]   # int64 exact


def test_wrench_units_become_si(tmp_path):
    df = pd.DataFrame({"time": [0.0, 0.001], "Fx": [1.0, 2.0], "Tz": [500.0, 1000.0]})
    p = _write(df, tmp_path / "w.csv", "csv")
    s = read_force_log(p, "time", ["Fx", "Tz"], units=["N", "N-mm"], kind="wrench")
    assert s.values.tolist() == [[1.0, 0.5], [2.0, 1.0]] and s.units == ["N", "N*m"]
    s = read_force_log(p, "time", ["Fx", "Tz"], units="lbf,lbf-in", kind="wrench")
    assert s.values[0] == pytest.approx([4.4482216152605, 500 * 4.4482216152605 * 0.0254])
    with pytest.raises(BadInput, match="does not fit kind 'wrench'"):
        read_force_log(p, "time", ["Fx", "Tz"], units="V", kind="wrench")
    with pytest.raises(BadInput, match="unknown unit"):
        read_force_log(p, "time", ["Fx", "Tz"], units="furlong", kind="wrench")
    with pytest.raises(BadInput, match="3 units given for 2 channels"):
        read_force_log(p, "time", ["Fx", "Tz"], units="N,N,N", kind="wrench")


# ---------------------------------------------------------------------------- bad input


def _bad(path: Path, match: str, **kw) -> BadInput:
    with pytest.raises(BadInput, match=match) as e:
        read_force_log(path, kw.pop("time", "time"), kw.pop("channels", GAUGES), **kw)
    assert str(path) in str(e.value)
    return e.value


@pytest.mark.parametrize("how", ["csv", "parquet", "mat7", "mat73-matrix"])
def test_bad_missing_columns(tmp_path, how):
    p = _write(_log(), tmp_path / f"f.{how}", how)
    _bad(p, "not in file: G9", channels=["G0", "G9"])


def test_bad_text_in_numbers(tmp_path):
    p = _write(_log(), tmp_path / "f.csv", "csv")
    lines = p.read_text().splitlines()
    cells = lines[41].split(",")
    cells[3] = "1.2.3"
    lines[41] = ",".join(cells)
    p.write_text("\n".join(lines) + "\n")
    e = _bad(p, "'1.2.3' in column G2 is not a number")
    assert e.where == "line 42"
    df = _log()
    df["G4"] = df["G4"].astype(str)                     # a text column, as some loggers write
    df.loc[7, "G4"] = "n/a?"
    e = _bad(_write(df, tmp_path / "f.parquet", "parquet"), "in column G4 is not a number")
    assert e.where == "row 8"


@pytest.mark.parametrize("column", ["time", "G3"])
def test_bad_nan_in_time_or_channels(tmp_path, column):
    df = _log()
    df.loc[20, column] = np.nan
    for how in ("csv", "mat73"):
        e = _bad(_write(df, tmp_path / f"f.{how}", how), f"column {column} has no value")
        assert e.where == ("line 22" if how == "csv" else "row 21")


def test_bad_non_increasing_time(tmp_path):
    df = _log()
    df.loc[30, "time"] = df.loc[29, "time"]
    e = _bad(_write(df, tmp_path / "f.mat", "mat7"), "time is not increasing")
    assert e.where == "row 31"


@pytest.mark.parametrize("how", ["csv", "parquet", "mat7", "mat73"])
def test_bad_truncated_file(tmp_path, how):
    p = _write(_log(), tmp_path / f"f.{how}", how)
    raw = p.read_bytes()
    p.write_bytes(raw[: len(raw) - 25] if how == "csv" else raw[: len(raw) // 2])
    e = _bad(p, "truncated" if how == "csv" else "cannot read")
    if how == "csv":
        assert e.where == f"line {N + 1}"


def _text(tmp_path: Path, text: str, name: str = "f.csv") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize("text, where", [
    ("time,Fx,Fy\n0.000,1.000,2.000\n0.001,3.000,40.002,4.000,5.000\n0.003,4.000,5.000\n",
     "line 3"),                                       # two rows merged: more fields
    ("time,Fx,Fy\n0,1,2,9\n0.001,3,4\n0.002,4,5\n", "line 2"),   # first row: pandas' index
    ("time,Fx,Fy\n0,1,2,9\n0.001,3,4,5\n0.002,4,5,6\n", "line 2"),
])
def test_bad_row_with_extra_fields(tmp_path, text, where):
    e = _bad(_text(tmp_path, text), "fields", channels=["Fx", "Fy"], units="N", kind="wrench")
    assert e.where == where


def test_trailing_separator_on_every_row_is_accepted(tmp_path):
    s = read_force_log(_text(tmp_path, "time,Fx,Fy\n0,1,2,\n0.001,3,4,\n"), "time",
                       ["Fx", "Fy"], units="N", kind="wrench")
    assert s.values.tolist() == [[1, 2], [3, 4]]


def test_bad_duplicate_header_names(tmp_path):
    e = _bad(_text(tmp_path, "time,time,G0\n0,1,2\n0.001,3,4\n"), "duplicate column name",
             channels=["G0"], units="V")
    assert e.where == "line 1"


@pytest.mark.parametrize("text", [
    "time,G0\n0.000,0.125\n0.001,0.25\n0.002,0.5",          # decimals vary: nothing to judge
    "time,G0\n0.000,0.125\n0.001,0.250\n0.002,1e-05",       # not a plain decimal number
    "time,G0\n0.000,0.125\n0.001,0.250\n0.002,nan",         # a gap, then refused as a gap
])
def test_last_line_without_line_break(tmp_path, text):
    p = _text(tmp_path, text)
    if text.endswith("nan"):
        _bad(p, "column G0 has no value", channels=["G0"])
    else:
        assert read_force_log(p, "time", ["G0"]).frames == 3


def test_bad_last_number_cut(tmp_path):
    p = _text(tmp_path, "time,G0\n0.000,0.125\n0.001,0.250\n0.002,0.5")   # 3 decimals, then 1
    assert _bad(p, "truncated", channels=["G0"]).where == "line 4"


def test_bad_time_out_of_range(tmp_path):
    e = _bad(_text(tmp_path, "time,G0\n0,1\n1e300,2\n"), "int64 nanosecond range",
             channels=["G0"])
    assert e.where == "line 3"
    e = _bad(_write(pd.DataFrame({"t": np.array([0, 10**12], dtype=np.int64), "G0": [1.0, 2]}),
                    tmp_path / "big.parquet", "parquet"), "int64 nanosecond range",
             time="t", channels=["G0"], time_unit="s")
    assert e.where == "row 2"


def test_bad_damaged_compressed_mat(tmp_path):
    p = tmp_path / "f.mat"
    scipy.io.savemat(p, {c: v.to_numpy() for c, v in _log().items()}, do_compression=True)
    raw = bytearray(p.read_bytes())
    raw[len(raw) // 2:len(raw) // 2 + 32] = bytes(32)
    p.write_bytes(bytes(raw))
    _bad(p, "cannot read")


def test_bad_format_and_parameters(tmp_path):
    p = tmp_path / "f.bin"
    p.write_bytes(b"\x00\x01\x02" * 100)
    _bad(p, "not a force log")
    good = _write(_log(), tmp_path / "f.csv", "csv")
    _bad(good, "kind must be", kind="volts")
    _bad(good, "time_unit must be", time_unit="h")
    _bad(good, "distinct", channels=["G0", "G0"])

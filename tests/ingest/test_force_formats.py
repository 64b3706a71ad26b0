"""The force logs labs really have: one known log written in every layout real rigs
and vendors' tools write (Simulink MAT arrays and structs, v7 and v7.3; ATI's DAQ F/T and Net
F/T CSV; QTM force-plate exports; CSV in other dialects), read back equal to the original after
unit conversion; MATLAB objects refused in one line naming them.

The layouts follow MathWorks' documentation (To File, To Workspace "Structure With Time",
``SimulinkRealTime.utils.getFileScopeData``, ``tout``/``yout``), ATI's manuals (DAQ F/T demo
"collect to file", Net F/T data log: a preamble with units and counts per unit, then ``Status
(hex), RDT Sequence, F/T Sequence, Fx..Tz, Time``) and QTM's force export as public loaders read
it (``FORCE_PLATE_*`` keys, ``SAMPLE TIME Force_X .. COP_Z``).
"""

from __future__ import annotations

import json
import shutil
import struct
from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.io

from core.errors import BadInput
from ingest.analog import samples_per_frame
from ingest.detect import detect_format
from ingest.force_log import read_force_log
from ingest.qtm_mat import write_mat73

N = 400
RATE = 1000.0


def _truth() -> tuple[np.ndarray, np.ndarray]:
    """Times (s, on a 1 kHz grid from 2.5 s) and six channels with 6 decimals."""
    rng = np.random.default_rng(28)
    t = np.round(2.5 + np.arange(N) / RATE, 6)
    v = np.round(rng.normal(0, 3, (N, 6)), 6)
    return t, v


T, V = _truth()
T_NS = np.rint(T * 1e9).astype(np.int64)


def _check(s, values=V, time_ns=T_NS, rtol=0.0, atol=1e-12) -> None:
    np.testing.assert_allclose(s.values, values, rtol=rtol, atol=atol)
    if time_ns is not None:
        assert s.time_ns.tolist() == time_ns.tolist()
    assert s.rate_hz == pytest.approx(RATE)


# ---------------------------------------------------------------------------- MAT


def _mat(path: Path, version: str, variables: dict) -> Path:
    if version == "7":
        scipy.io.savemat(path, variables, do_compression=True)
    else:
        write_mat73(path, variables)
    return path


def _swt(values: np.ndarray = V) -> dict:
    """To Workspace "Structure With Time"."""
    return {"time": T[:, None], "signals": {"values": values, "dimensions": 6.0, "label": ""},
            "blockName": "nano17_logger/To Workspace"}


MAT_LAYOUTS = {
    "to_file_rows": lambda: {"force_log": np.vstack([T, V.T])},         # (1 + 6) x N
    "columns": lambda: {"force_log": np.column_stack([T, V])},          # N x (1 + 6)
    "structure_with_time": lambda: {"force_log": _swt()},
    "file_scope": lambda: {"fsd": {"data": np.column_stack([V, T]), "numSignals": 6.0,
                                   "signalNames": [f"Nano17/G{i}" for i in range(6)]}},
    "tout_yout": lambda: {"tout": T[:, None], "yout": V},
    "tout_yout_struct": lambda: {"tout": T[:, None], "yout": _swt()},
}


@pytest.mark.parametrize("version", ["7", "7.3"])
@pytest.mark.parametrize("layout", list(MAT_LAYOUTS))
def test_simulink_mat_layouts_read_by_signal_number(tmp_path, layout, version):
    p = _mat(tmp_path / "force.mat", version, MAT_LAYOUTS[layout]())
    assert detect_format(p) == "force_mat"
    s = read_force_log(p, "time", [1, 2, 3, 4, 5, 6])
    _check(s)
    assert s.units == ["V"] * 6 and s.meta["time_column"] == "time"


@pytest.mark.parametrize("version", ["7", "7.3"])
def test_struct_field_path_picks_one_of_several_logs(tmp_path, version):
    """Two logged structs: refused until force.variable names one, by struct or field path."""
    other = _swt(V[:, ::-1].copy())
    p = _mat(tmp_path / "force.mat", version, {"force_log": _swt(), "other": other})
    with pytest.raises(BadInput, match="several logs .*force.variable"):
        read_force_log(p, "time", [1, 2, 3, 4, 5, 6])
    for variable in ("force_log", "force_log.signals.values"):
        _check(read_force_log(p, "time", [1, 2, 3, 4, 5, 6], variable=variable))
    _check(read_force_log(p, "time", [6, 5, 4, 3, 2, 1], variable="other"))
    with pytest.raises(BadInput, match="force_log.signals has no 'valuez'"):
        read_force_log(p, "time", [1], variable="force_log.signals.valuez")


def test_simulink_level4_to_file_and_struct_variants(tmp_path):
    """To File in MAT Level 4 (old Simulink, xPC file logs); a Structure With Time of two
    signals (a struct array, v7 and v7.3 as MATLAB lays one out); Save format "Structure"
    (time empty): timed by force.rate_hz, refused without it."""
    p = tmp_path / "tofile.mat"
    scipy.io.savemat(p, {"ans": np.vstack([T, V.T])}, format="4")
    assert detect_format(p) == "force_mat"
    _check(read_force_log(p, "time", [1, 2, 3, 4, 5, 6]))
    sig = np.empty((1, 2), dtype=[("values", "O"), ("dimensions", "O"), ("label", "O")])
    sig[0, 0], sig[0, 1] = (V[:, :2], 2.0, "F"), (V[:, 2:], 4.0, "rest")
    p = tmp_path / "two.mat"
    scipy.io.savemat(p, {"x": {"time": T[:, None], "signals": sig}})
    _check(read_force_log(p, "time", [1, 2, 3, 4, 5, 6]))
    p = _mat(tmp_path / "two73.mat", "7.3", {"x": {"time": T[:, None], "signals": {}}})
    with h5py.File(p, "r+") as f:                      # signals(1:2): fields of references
        g = f["x/signals"]
        refs = f.require_group("#refs#")
        for field, parts in (("values", (V[:, :2], V[:, 2:])), ("dimensions", (2.0, 4.0))):
            r = np.empty((2, 1), dtype=h5py.ref_dtype)
            for i, part in enumerate(parts):
                ds = refs.create_dataset(f"{field}{i}", data=np.atleast_2d(part).T)
                ds.attrs["MATLAB_class"] = np.bytes_("double")
                r[i, 0] = ds.ref
            g.create_dataset(field, data=r)
    _check(read_force_log(p, "time", [1, 2, 3, 4, 5, 6]))
    p = _mat(tmp_path / "nostamp.mat", "7", {"x": {"time": np.zeros((0, 0)),
                                                    "signals": {"values": V}}})
    _check(read_force_log(p, "time", [1, 2, 3, 4, 5, 6], rate_hz=RATE),
           time_ns=np.arange(N) * 1_000_000)
    with pytest.raises(BadInput, match="give force.rate_hz for a log without one"):
        read_force_log(p, "time", [1, 2, 3, 4, 5, 6])


def test_file_scope_signal_names_and_wrench_units(tmp_path):
    """getFileScopeData's signalNames name the channels; a wrench log in N and N-mm."""
    names = ["Fx", "Fy", "Fz", "Tx", "Ty", "Tz"]
    p = _mat(tmp_path / "fs.mat", "7", {"fsd": {"data": np.column_stack([V, T]),
                                                  "numSignals": 6.0, "signalNames": names}})
    s = read_force_log(p, "time", names, kind="wrench", units="N,N,N,N-mm,N-mm,N-mm")
    _check(s, V * [1, 1, 1, 1e-3, 1e-3, 1e-3])
    assert s.units == ["N", "N", "N", "N*m", "N*m", "N*m"]


def _element(dtype: int, payload: bytes) -> bytes:
    """A MAT v5 data element: tag, payload, padding to 8 bytes."""
    return struct.pack("<II", dtype, len(payload)) + payload + bytes(-len(payload) % 8)


def _mcos(path: Path, cls: str, version: str = "7.3") -> Path:
    """A file holding a MATLAB object ``ts`` as MATLAB writes one. v7.3: uint32 handle data
    with the class name and MATLAB_object_decode, contents under #subsystem#. v7 (MAT-File
    Format: miMATRIX of class mxOPAQUE_CLASS = 17, then the variable name, the object type
    "MCOS", the class name and a uint32 matrix of handle data)."""
    handle = np.array([3707764736, 2, 1, 1, 1, 1], np.uint32)
    if version == "7.3":
        write_mat73(path, {"note": "x"})
        with h5py.File(path, "r+") as f:
            ds = f.create_dataset("ts", data=handle[:, None].T)
            ds.attrs["MATLAB_class"] = np.bytes_(cls)
            ds.attrs["MATLAB_object_decode"] = np.int32(3)
            f.create_group("#subsystem#")
        return path
    mi_int8, mi_int32, mi_uint32, mi_matrix = 1, 5, 6, 14

    def flags(mx_class: int) -> bytes:
        return _element(mi_uint32, struct.pack("<II", mx_class, 0))

    data = _element(mi_matrix, flags(13) + _element(mi_int32, struct.pack("<ii", 6, 1))
                    + _element(mi_int8, b"") + _element(mi_uint32, handle.tobytes()))
    body = flags(17) + b"".join(_element(mi_int8, t) for t in (b"ts", b"MCOS",
                                                               cls.encode())) + data
    head = b"MATLAB 5.0 MAT-file, written by a test".ljust(116, b" ") + bytes(8)
    path.write_bytes(head + struct.pack("<H", 0x0100) + b"IM" + _element(mi_matrix, body))
    return path


@pytest.mark.parametrize("version", ["7", "7.3"])
@pytest.mark.parametrize("cls, how", [("timeseries", "ts.Time"), ("table", "table2array"),
                                      ("Simulink.SimulationData.Dataset", "Values.Data")])
def test_matlab_objects_refused_in_one_line_saying_how_to_save_them(tmp_path, cls, how,
                                                                     version):
    p = _mcos(tmp_path / "obj.mat", cls, version)
    with pytest.raises(BadInput, match=f"ts is a MATLAB {cls} object, which no Python reader "
                                       "decodes") as e:
        read_force_log(p, "time", [1, 2, 3, 4, 5, 6])
    assert how in str(e.value) and "\n" not in str(e.value)


# ---------------------------------------------------------------------------- ATI CSV


def _fmt(x: float, decimal: str) -> str:
    return f"{x:.6f}".replace(".", decimal)


def _daq_csv(path: Path, names: list[str], values: np.ndarray, sep: str = ",",
             decimal: str = ".", averaging: int = 1, paused: bool = False) -> Path:
    """ATI's DAQ F/T .NET demo log (formDataCollection.vb, as in the public repository
    meekeech/Audio-Feedback-Device @ 6245565d : ATIDAQDotnetDemo/formDataCollection.vb): every
    field quoted and joined by the culture's list separator; the column names, then the
    capture's metadata fields on the same line; the records at Frequency / Averaging Level."""
    meta = [f"Frequency = {int(RATE) * averaging}", f"Averaging Level = {averaging}",
            "F/T Serial Number = FT14048", "Time Started = 26.11.2026 09:00:02"]
    lines = ['Paused for 100 milliseconds before saving data - first sample recorded here was '
             'collected 100 milliseconds after the time reported as "Time Started".'] \
        if paused else []
    lines.append(sep.join(f'"{x}"' for x in (*names, *meta)))
    lines += [sep.join(f'"{_fmt(x, decimal)}"' for x in r) for r in values]
    path.write_text("\r\n".join(lines) + "\r\n", encoding="utf-8")
    return path


ATI_WRENCH = ["Force X (N)", "Force Y (N)", "Force Z (N)", "Torque X (N-mm)",
              "Torque Y (N-mm)", "Torque Z (N-mm)"]


@pytest.mark.parametrize("sep, decimal", [(",", "."), (";", ",")])
def test_ati_daq_ft_csv_wrench_timed_by_its_frequency(tmp_path, sep, decimal):
    p = _daq_csv(tmp_path / "daq.csv", ATI_WRENCH, V, sep, decimal)
    assert detect_format(p) == "force_ati_daq"
    s = read_force_log(p, None, ATI_WRENCH, kind="wrench")
    _check(s, V * [1, 1, 1, 1e-3, 1e-3, 1e-3], time_ns=np.arange(N) * 1_000_000)
    assert s.units == ["N", "N", "N", "N*m", "N*m", "N*m"] and s.meta["timed_by"] == "rate"


def test_ati_daq_ft_csv_gauges_by_number(tmp_path):
    """Gauges with the thermistor column, records averaged 4 to 1 (the rate is Frequency / 4),
    after the demo's "Paused for ..." line."""
    therm = np.column_stack([V, np.full(N, 0.25)])
    p = _daq_csv(tmp_path / "daq.csv", [*(f"G{i}" for i in range(6)), "Therm"], therm,
                 averaging=4, paused=True)
    s = read_force_log(p, None, [1, 2, 3, 4, 5, 6])
    _check(s, time_ns=np.arange(N) * 1_000_000)
    with pytest.raises(BadInput, match="force.rate_hz is 500 Hz but the file states 1000"):
        read_force_log(p, None, [1, 2, 3, 4, 5, 6], rate_hz=500.0)


def _java(x: float) -> str:
    """A double as Java's Double.toString writes it (ATI's demo is Java)."""
    if x == 0:
        return "0.0"
    if 1e-3 <= abs(x) < 1e7:
        return repr(float(x))
    mantissa, exponent = f"{x:.15e}".split("e")
    return f"{float(mantissa)!r}E{int(exponent)}"


def _netft_csv(path: Path, counts: bool = False) -> Path:
    """ATI's Net F/T demo log (NetFTSampleGUI 1.1.1, "collect to file"): a "key: value"
    preamble, the column line, then quoted rows: status, sequences, the wrench already divided
    by the counts per unit, and the time as Java's default date-time (whole seconds). With
    ``counts``: an older log of raw counts (whole numbers) and a "key","value" preamble."""
    per_unit = [1_000_000] * 3 + [1_000_000] * 3
    if counts:
        pre = ['"RDT Sample Rate","1000"', '"Force Units","N"', '"Torque Units","Nm"',
               f'"Counts per Unit Force","{per_unit[0]}"',
               f'"Counts per Unit Torque","{per_unit[3]}"']
    else:
        pre = ["Start Time: 11/26/26 9:00 AM", "RDT Sample Rate: 1000",
               '"PLEASE NOTE: The sample rate is read from the Net F/T when the program '
               "starts.  If you have changed the sample rate since the program started, this "
               'will be incorrect."', "Force Units: N", "Counts per Unit Force: 1000000.0",
               "Torque Units: Nm", "Counts per Unit Torque: 1000000.0"]
    head = "Status (hex), RDT Sequence, F/T Sequence, Fx, Fy, Fz, Tx, Ty, Tz, Time"
    rows = []
    for i, r in enumerate(V):
        wrench = ([str(c) for c in np.rint(r * per_unit).astype(np.int64)] if counts
                  else [_java(x) for x in r])
        clock = f"Nov 26, 2026 9:00:{2 + (500 + i) // 1000:02d} AM"
        rows.append(",".join(f'"{x}"' for x in ["0x0", 1000 + i, 7000 + 7 * i, *wrench,
                                                clock]))
    path.write_text("\r\n".join([*pre, head, *rows]) + "\r\n")
    return path


@pytest.mark.parametrize("counts", [False, True])
def test_ati_netft_csv_timed_by_rdt_sequence(tmp_path, counts):
    """The clock time holds whole seconds: the samples are timed by the RDT sequence at the
    RDT rate from the first one; raw counts are divided by the counts per unit."""
    p = _netft_csv(tmp_path / "netft.csv", counts)
    assert detect_format(p) == "force_ati_netft"
    s = read_force_log(p, None, ["Fx", "Fy", "Fz", "Tx", "Ty", "Tz"], kind="wrench")
    start = np.datetime64("2026-11-26T09:00:02", "ns").astype(np.int64)
    _check(s, time_ns=start + np.arange(N) * 1_000_000)
    assert s.meta["units_in_file"] == ["N", "N", "N", "Nm", "Nm", "Nm"]


# ---------------------------------------------------------------------------- QTM force plate


def _force_plate(path: Path, column_line: bool | str = True, rate: float = RATE) -> Path:
    """QTM's force export; ``column_line`` "names": the nine names without SAMPLE and TIME,
    as a public MATLAB writer of QTM force files has it."""
    keys = [("NO_OF_SAMPLES", str(N)), ("FREQUENCY", f"{rate:g}"),
            ("TIME_STAMP", "2026-11-26, 09:00:00.000\t123.456"), ("FIRST_SAMPLE", "1"),
            ("DESCRIPTION", "Force data in local (force plate) coordinates"),
            ("DATA_INCLUDED", "Force"), ("FORCE_PLATE_TYPE", "Kistler"),
            ("FORCE_PLATE_MODEL", "9260AA"), ("FORCE_PLATE_NAME", "Force-plate 1"),
            ("FORCE_PLATE_CORNER_POSX_POSY_X", "300.000"),
            ("FORCE_PLATE_CORNER_POSX_POSY_Y", "200.000"), ("FORCE_PLATE_LENGTH", "600.000"),
            ("FORCE_PLATE_WIDTH", "400.000")]
    lines = [f"{k}\t{v}" for k, v in keys]
    cop = np.full((N, 3), 12.5)
    if column_line:
        lines.append(("" if column_line == "names" else "SAMPLE\tTIME\t") +
                     "Force_X\tForce_Y\tForce_Z\tMoment_X\tMoment_Y\tMoment_Z\tCOP_X\tCOP_Y\tCOP_Z")
    for i in range(N):
        lead = [str(i + 1), f"{i / rate:.5f}"] if column_line is True else []
        lines.append("\t".join([*lead, *(f"{x:.6f}" for x in (*V[i], *cop[i]))]))
    path.write_text("\r\n".join(lines) + "\r\n")
    return path


@pytest.mark.parametrize("column_line, trailing_tab", [(True, False), (False, False),
                                                     (True, True), ("names", True)])
def test_qtm_force_plate_export_is_the_sensor(tmp_path, column_line, trailing_tab):
    p = _force_plate(tmp_path / "trial_f_1.tsv", column_line)
    if trailing_tab:                                   # every line ends in a tab, as QTM's do
        p.write_text(p.read_text().replace("\n", "\t\n"))
    assert detect_format(p) == "qtm_tsv_force"
    wrench = ["Force_X", "Force_Y", "Force_Z", "Moment_X", "Moment_Y", "Moment_Z"]
    s = read_force_log(p, None, wrench, kind="wrench")
    _check(s, time_ns=np.arange(N) * 1_000_000)
    assert s.units == ["N", "N", "N", "N*m", "N*m", "N*m"] and s.meta["clock"] == "mocap"


def test_a_force_plate_at_a_rate_its_time_column_rounds_is_timed_by_its_frequency(tmp_path):
    """At 1200 Hz QTM's 5-decimal TIME is off by up to 4 us a sample: the samples are timed
    by FREQUENCY (exactly 1200 Hz, as the mocap's analog board would be), TIME only checked."""
    p = _force_plate(tmp_path / "trial_f_1.tsv", rate=1200.0)
    s = read_force_log(p, None, ["Force_X", "Force_Y", "Force_Z", "Moment_X", "Moment_Y",
                                 "Moment_Z"], kind="wrench")
    assert s.rate_hz == pytest.approx(1200.0, rel=1e-6)           # from whole nanoseconds
    np.testing.assert_allclose(s.time_ns, np.arange(N) / 1200.0 * 1e9, rtol=0, atol=1)
    assert samples_per_frame(p, s.rate_hz, 300.0) == 4


# ---------------------------------------------------------------------------- CSV dialects


def _dialect(path: Path, sep: str, decimal: str, quote: bool = False,
             comments: bool = False) -> Path:
    q = '"' if quote else ""
    names = ["time", *(f"G{i}" for i in range(6))]
    lines = ["# logger: bench rig 2", "# units: s, V"] if comments else []
    lines.append(sep.join(f"{q}{n}{q}" for n in names))
    lines += [sep.join(f"{q}{_fmt(x, decimal)}{q}" for x in (t, *r))
              for t, r in zip(T, V, strict=True)]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("sep, decimal, quote, comments", [
    (";", ",", False, False), (";", ".", False, False), (",", ".", True, False),
    (";", ",", True, False), ("\t", ".", False, True), ("|", ".", False, False),
    (" ", ".", False, True),
])
def test_csv_dialects_are_sniffed(tmp_path, sep, decimal, quote, comments):
    p = _dialect(tmp_path / "log.txt", sep, decimal, quote, comments)
    assert detect_format(p) == "force_csv"
    _check(read_force_log(p, "time", [f"G{i}" for i in range(6)]))


def test_units_line_excel_sep_line_percent_comments_and_clock_times(tmp_path):
    """A line of units under the names (loggers, LabChart), Excel's "sep=;" first line,
    MATLAB's % comments, and a time column of dates and clock times."""
    rows = [";".join(_fmt(x, ",") for x in (t, *r)) for t, r in zip(T, V, strict=True)]
    p = tmp_path / "units.csv"
    p.write_text("\n".join(["sep=;", "time;Fx;Fy;Fz;Tx;Ty;Tz", "s;N;N;N;N-mm;N-mm;N-mm",
                             *rows]) + "\n")
    s = read_force_log(p, "time", ["Fx", "Fy", "Fz", "Tx", "Ty", "Tz"], kind="wrench")
    _check(s, V * [1, 1, 1, 1e-3, 1e-3, 1e-3])
    p = tmp_path / "pct.txt"
    p.write_text("% written by dlmwrite\n% time in ms\ntime\tG0\n" + "".join(
        f"{i}\t{x:.6f}\n" for i, x in enumerate(V[:, 0])) + "% end\n")
    s = read_force_log(p, "time", ["G0"], time_unit="ms")
    assert s.frames == N and s.rate_hz == pytest.approx(RATE)
    p = tmp_path / "clock.csv"
    stamps = (np.datetime64("2026-11-26T09:00:02.500") + np.arange(N) *
              np.timedelta64(1, "ms")).astype(str)
    p.write_text("Timestamp,G0\n" + "".join(f"{c},{x:.6f}\n" for c, x in
                                             zip(stamps, V[:, 0], strict=True)))
    s = read_force_log(p, "Timestamp", ["G0"])
    start = np.datetime64("2026-11-26T09:00:02.500", "ns").astype(np.int64)
    assert s.time_ns.tolist() == (start + np.arange(N) * 1_000_000).tolist()


def test_dialect_that_cannot_be_sniffed_is_stated(tmp_path):
    """Decimal commas in some numbers and points in others: refused until force.decimal is
    stated (here the points are thousands marks? no: the file is inconsistent)."""
    p = tmp_path / "mixed.csv"
    p.write_text("time;G0\n0,000;1.5\n0,001;2,5\n0,002;3,5\n")
    with pytest.raises(BadInput, match="state force.decimal"):
        read_force_log(p, "time", ["G0"])
    p.write_text("time;G0\n0;1\n1;2\n2;3\n")                # integers: either mark reads
    s = read_force_log(p, "time", ["G0"], time_unit="ms", delimiter=";", decimal=",")
    assert s.time_ns.tolist() == [0, 1_000_000, 2_000_000] and s.values[:, 0].tolist() == [1, 2, 3]


def test_headerless_csv_numbers_time_first(tmp_path):
    p = tmp_path / "bare.csv"
    rows = (",".join(f"{x:.6f}" for x in (t, *r)) for t, r in zip(T, V, strict=True))
    p.write_text("\n".join(rows) + "\n")
    _check(read_force_log(p, "time", [1, 2, 3, 4, 5, 6]))


def test_integer_ms_time_and_unit_in_the_name(tmp_path):
    p = tmp_path / "ms.csv"
    p.write_text("t_ms,G0\n" + "".join(f"{i},{x:.6f}\n" for i, x in enumerate(V[:, 0])))
    s = read_force_log(p, "t_ms", ["G0"])                   # "_ms" states the unit
    assert s.time_ns[-1] == (N - 1) * 1_000_000 and s.rate_hz == pytest.approx(RATE)
    p.write_text("time,G0\n" + "".join(f"{i},{x:.6f}\n" for i, x in enumerate(V[:, 0])))
    assert read_force_log(p, "time", ["G0"], time_unit="ms").rate_hz == pytest.approx(RATE)


# ---------------------------------------------------------------------------- volts to N


def test_scale_and_offset_turn_volts_into_newtons(tmp_path):
    """An F/T interface's analog output: (V - offset) x N/V, N m/V; a mV log scaled per V."""
    scale = [20.0, 20.0, 60.0, 0.5, 0.5, 0.5]
    offset = [0.01, -0.02, 0.0, 0.0, 0.005, 0.0]
    volts = V / 10
    p = tmp_path / "v.csv"
    names = ["time", *(f"AI{i} (mV)" for i in range(6))]
    rows = (",".join(f"{x:.6f}" for x in (t, *(r * 1000))) for t, r in zip(T, volts, strict=True))
    p.write_text(",".join(names) + "\n" + "\n".join(rows) + "\n")
    s = read_force_log(p, "time", names[1:], kind="wrench", units="N,N,N,N*m,N*m,N*m",
                       scale=scale, offset=offset)
    _check(s, (volts - offset) * scale, atol=1e-9)
    with pytest.raises(BadInput, match="is in mV, which does not fit force.kind = 'wrench' "
                                       r"\(give force.scale"):
        read_force_log(p, "time", names[1:], kind="wrench")


# ---------------------------------------------------------------------------- inspect


def _every_layout(d: Path) -> dict[str, Path]:
    """Each generated layout (and some damaged ones) in its own file."""
    out = {}
    for version in ("7", "7.3"):
        for name, make in MAT_LAYOUTS.items():
            out[f"mat{version}_{name}"] = _mat(d / f"{name}_{version}.mat", version, make())
    out["mcos_timeseries_7"] = _mcos(d / "mcos7.mat", "timeseries", "7")
    out["mcos_dataset_73"] = _mcos(d / "mcos73.mat", "Simulink.SimulationData.Dataset")
    out["daq_gauge"] = _daq_csv(d / "daq_g.csv", [f"G{i}" for i in range(6)], V)
    out["daq_wrench_eu"] = _daq_csv(d / "daq_w.csv", ATI_WRENCH, V, ";", ",")
    out["netft"] = _netft_csv(d / "netft.csv")
    out["force_plate"] = _force_plate(d / "t_f_1.tsv")
    out["force_plate_old"] = _force_plate(d / "t_f_2.tsv", column_line=False)
    for i, args in enumerate([(";", ",", False, False), (",", ".", True, False),
                              ("\t", ".", False, True)]):
        out[f"dialect{i}"] = _dialect(d / f"dialect{i}.txt", *args)
    damaged = {"empty.csv": b"", "one_line.csv": b"time,G0\n", "words.txt": b"hello world\n",
               "binary.bin": bytes(range(256)) * 4, "text_in_numbers.csv":
               b"time;G0\n0,0;1,0\n0,1;x\n0,2;2,0\n"}
    for name, raw in damaged.items():
        (d / name).write_bytes(raw)
        out[name] = d / name
    for name in ("to_file_rows_7.3.mat", "structure_with_time_7.mat"):
        raw = (d / name).read_bytes()
        (d / f"cut_{name}").write_bytes(raw[: len(raw) // 2])
        out[f"cut_{name}"] = d / f"cut_{name}"
    rng = np.random.default_rng(5)                   # bytes overwritten, seeded
    for name in ("to_file_rows_7.3.mat", "structure_with_time_7.3.mat", "tout_yout_7.mat",
                 "netft.csv", "daq_w.csv", "t_f_1.tsv"):
        raw = (d / name).read_bytes()
        for k in range(4):
            b = bytearray(raw)
            at = rng.integers(0, len(b), 8)
            b[at[0]:at[0] + 8] = rng.integers(0, 256, 8, dtype=np.uint8).tobytes()
            for i in at[1:]:
                b[i] = int(rng.integers(0, 256))
            (d / f"spoilt{k}_{name}").write_bytes(bytes(b))
            out[f"spoilt{k}_{name}"] = d / f"spoilt{k}_{name}"
    return out


def _inspect(path: Path):
    from click.testing import CliRunner

    from pipeline.cli import cli

    return CliRunner().invoke(cli, ["inspect", str(path), "--json"])


READ_BACK = {  # layout -> (frames, rate) inspect must report
    **{f"mat{v}_{k}": (N, RATE) for v in ("7", "7.3") for k in MAT_LAYOUTS},
    "daq_gauge": (N, RATE), "daq_wrench_eu": (N, RATE), "netft": (N, RATE),
    "force_plate": (N, RATE), "force_plate_old": (N, RATE),
    "dialect0": (N, RATE), "dialect1": (N, RATE), "dialect2": (N, RATE),
}


def test_inspect_never_ends_in_a_traceback(tmp_path, real_samples):
    """Every layout and every damaged file: exit 0 with the log's frames and rate, or 2 with
    one line naming the file; never 1 (a traceback)."""
    import json

    files = _every_layout(tmp_path)
    files.update({p.name: p for p in sorted(real_samples.rglob("*")) if p.is_file()})
    for name, path in files.items():
        res = _inspect(path)
        assert res.exit_code in (0, 2), (name, res.output, res.stderr, res.exception)
        if name in READ_BACK:
            assert res.exit_code == 0, (name, res.stderr)
            s = json.loads(res.output)
            assert (s["frames"], s["rate_hz"]) == (READ_BACK[name][0],
                                                   pytest.approx(READ_BACK[name][1])), name
            assert len(s["channels"]) >= 6, name
        elif res.exit_code == 2:
            lines = res.stderr.strip().splitlines()
            assert len(lines) == 1 and str(path) in lines[0], (name, res.stderr)


def test_inspect_reads_a_log_as_its_session_says(tmp_path):
    """Integer ms with time_unit = "ms" in a session.toml beside the log: the rate in ms."""
    (tmp_path / "force.csv").write_text(
        "time,G0,G1,G2,G3,G4,G5\n" + "".join(
            f"{75368 + i}," + ",".join(f"{x:.6f}" for x in V[i]) + "\n" for i in range(N)))
    (tmp_path / "ft.cal").write_text("<FTSensor/>")
    (tmp_path / "trial.tsv").write_text("")
    (tmp_path / "session.toml").write_text(
        '[mocap]\nfile = "trial.tsv"\nphantom_markers = ["A", "B", "C", "D"]\n'
        'indenter_markers = ["I1", "I2", "I3"]\n[force]\nfile = "force.csv"\n'
        'time_unit = "ms"\nchannels = [1, 2, 3, 4, 5, 6]\ncalibration = "ft.cal"\n')
    import json

    res = _inspect(tmp_path / "force.csv")
    assert res.exit_code == 0, res.stderr
    s = json.loads(res.output)
    assert s["frames"] == N and s["rate_hz"] == pytest.approx(RATE)
    assert s["details"]["time_unit"] == "ms" and s["channels"] == [f"G{i}" for i in range(6)]


# ---------------------------------------------------------------------------- session.toml


@pytest.mark.parametrize("layout, force", [
    ("to_file", 'file = "f.mat"\nchannels = [1, 2, 3, 4, 5, 6]'),
    ("swt_path", 'file = "f.mat"\nvariable = "log.signals.values"\n'
                 "channels = [1, 2, 3, 4, 5, 6]"),
    ("daq_eu", 'file = "f.csv"\nkind = "wrench"\ndelimiter = ";"\ndecimal = ","\n'
               f"channels = {json.dumps(ATI_WRENCH)}"),
    ("plate", 'file = "f.tsv"\nkind = "wrench"\nchannels = ["Force_X", "Force_Y", "Force_Z", '
              '"Moment_X", "Moment_Y", "Moment_Z"]'),
])
def test_session_toml_keys_reach_the_reader(tmp_path, layout, force):
    """The [force] keys of each layout's example in docs/stages.md, through read_session and
    read_force (what ingest calls)."""
    from data_schema.session import read_session
    from ingest.force_source import read_force

    if layout == "to_file":
        _mat(tmp_path / "f.mat", "7.3", {"ans": np.vstack([T, V.T])})
    elif layout == "swt_path":
        _mat(tmp_path / "f.mat", "7", {"log": _swt(), "other": _swt()})
    elif layout == "daq_eu":
        _daq_csv(tmp_path / "f.csv", ATI_WRENCH, V, ";", ",")
    else:
        _force_plate(tmp_path / "f.tsv")
    (tmp_path / "trial.tsv").write_text("")
    (tmp_path / "ft.cal").write_text("")
    (tmp_path / "session.toml").write_text(
        '[mocap]\nfile = "trial.tsv"\nphantom_markers = ["A", "B", "C", "D"]\n'
        f'indenter_markers = ["I1", "I2", "I3"]\n[force]\ncalibration = "ft.cal"\n{force}\n')
    s = read_force(read_session(tmp_path).force)
    if layout in ("to_file", "swt_path"):
        _check(s)
    else:
        _check(s, V * ([1, 1, 1, 1e-3, 1e-3, 1e-3] if layout == "daq_eu" else 1),
               time_ns=np.arange(N) * 1_000_000)


@pytest.mark.parametrize("yout", ["array", "struct"])
@pytest.mark.parametrize("version", ["7", "7.3"])
def test_session_toml_may_name_tout_the_time_column(tmp_path, version, yout):
    """A model's default outputs saved with scipy.io.savemat (v7; v7.3 as MATLAB writes it):
    ``time_column = "tout"`` names the time the file calls tout; a name the file does not have
    is refused, listing what it has."""
    from data_schema.session import read_session
    from ingest.force_source import read_force

    layout = "tout_yout" if yout == "array" else "tout_yout_struct"
    _mat(tmp_path / "f.mat", version, MAT_LAYOUTS[layout]())
    (tmp_path / "trial.tsv").write_text("")
    (tmp_path / "ft.cal").write_text("")
    for time_column in ("tout", "tin"):
        (tmp_path / "session.toml").write_text(
            '[mocap]\nfile = "trial.tsv"\nphantom_markers = ["A", "B", "C", "D"]\n'
            'indenter_markers = ["I1", "I2", "I3"]\n[force]\ncalibration = "ft.cal"\n'
            f'file = "f.mat"\ntime_column = "{time_column}"\nchannels = [1, 2, 3, 4, 5, 6]\n')
        force = read_session(tmp_path).force
        if time_column == "tout":
            _check(read_force(force))
        else:
            with pytest.raises(BadInput, match=r"time column not in file: tin \(the file has: "
                                               r"time, 1, 2"):
                read_force(force)


# ---------------------------------------------------------------------------- pipeline ingest


@pytest.fixture(scope="module")
def twin(tmp_path_factory) -> tuple[Path, np.ndarray]:
    """A small twin session and its force log as numbers (read with the csv module)."""
    import csv

    from sim.twin.synth_params import SynthParams
    from sim.twin.synth_stage import run_synth

    folder = run_synth(None, tmp_path_factory.mktemp("twin") / "s",
                       SynthParams(seed=1, locations=1, repeats=1))
    with open(folder / "force.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["time", *(f"G{i}" for i in range(6)), "trigger"]
    return folder, np.array(rows[1:], dtype=float)


def _force_table(folder: Path, keys: str) -> None:
    """session.toml's [force] table replaced by ``keys`` (and the calibration)."""
    text = (folder / "session.toml").read_text()
    start = text.index("[force]")
    end = text.index("\n[", start + 1)
    cal = next(x for x in text[start:end].splitlines() if x.startswith("calibration"))
    (folder / "session.toml").write_text(f"{text[:start]}[force]\n{keys}\n{cal}{text[end:]}")


@pytest.mark.parametrize("layout", ["to_file_73", "swt_7", "eu_csv"])
def test_pipeline_ingest_reads_the_twin_log_in_other_layouts(twin, tmp_path, layout):
    """The twin's force log rewritten as a Simulink To File array (v7.3, the trigger as signal
    7), a Structure With Time (v7) and a ';' CSV with decimal commas: ingest stores the same
    samples as the CSV holds."""
    from ingest.mcap_io import read_raw_mcap

    src, log = twin
    folder = tmp_path / "s"
    shutil.copytree(src, folder)
    t, gauges, trig = log[:, 0], log[:, 1:7], log[:, 7]
    if layout == "to_file_73":
        write_mat73(folder / "log.mat", {"ans": np.vstack([t, gauges.T, trig])})
        keys = 'file = "log.mat"\nchannels = [1, 2, 3, 4, 5, 6]\ntrigger_column = 7'
    elif layout == "swt_7":
        scipy.io.savemat(folder / "log.mat", {"nano17": {
            "time": t[:, None], "signals": {"values": np.column_stack([gauges, trig]),
                                            "dimensions": 7.0, "label": ""}}})
        keys = 'file = "log.mat"\nchannels = [1, 2, 3, 4, 5, 6]\ntrigger_column = 7'
    else:
        text = (folder / "force.csv").read_text().replace(",", ";").replace(".", ",")
        (folder / "log.csv").write_text(text)
        keys = 'file = "log.csv"\nchannels = ["G0", "G1", "G2", "G3", "G4", "G5"]\n' \
               'trigger_column = "trigger"'
    _force_table(folder, keys)
    (folder / "force.csv").unlink()                  # only the new layout is there to read
    from click.testing import CliRunner

    from pipeline.cli import cli

    out = tmp_path / "s.mcap"
    res = CliRunner().invoke(cli, ["-q", "ingest", str(folder), "--out", str(out), "--no-rrd"])
    assert res.exit_code == 0, res.stderr
    s = read_raw_mcap(out).force
    np.testing.assert_array_equal(s.values, gauges)
    np.testing.assert_array_equal(s.trigger, trig)
    assert s.time_ns.tolist() == np.rint(t * 1e9).astype(np.int64).tolist()


def test_a_time_unit_the_file_contradicts_is_refused(tmp_path):
    """`t_ms` read as seconds would make a 1 kHz log a 1 Hz one: refused, as channel units."""
    p = tmp_path / "force.csv"
    p.write_text("t_ms,G0,G1,G2,G3,G4,G5\n" + "".join(
        f"{i},0.1,0.2,0.3,0.4,0.5,0.6\n" for i in range(20)))
    with pytest.raises(BadInput, match="time_unit is 's', but the file states 'ms'"):
        read_force_log(p, "t_ms", [f"G{i}" for i in range(6)], time_unit="s")
    assert read_force_log(p, "t_ms", [f"G{i}" for i in range(6)]).rate_hz == \
        pytest.approx(1000.0)

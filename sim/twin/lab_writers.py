"""Writers of the files a phantom lab produces, byte for byte in the lab's formats.

* QTM TSV 3D export (QTM 2021 style): header keys, ``EVENT`` lines, ``MARKER_NAMES``,
  ``TRAJECTORY_TYPES``, a ``Frame Time <name> X <name> Y <name> Z ...`` column line ending in a
  tab, CRLF line ends, millimetres with 3 decimals, gaps as empty cells.
* QTM TSV 6D export: ``BODY_NAMES`` and a column line ``Frame Time <body> X Y Z Roll Pitch Yaw
  Residual Rot[0] .. Rot[8]`` (QTM's standard Euler angles: roll about x, then pitch about the
  new y, then yaw about the new z, degrees; the rotation matrix column-major); a lost body is
  all zeros with residual -1.
* The Speedgoat force log as a researcher exports it: CSV (``time`` in s and one column per
  signal) and MAT v7 (one column vector per signal).
* The mocap system's own exports when the force goes through its analog board: a C3D file
  (points in mm, residual -1 in gaps, analog channels with ``ANALOG:LABELS`` cut short and
  repeated as real exports have them, the full names in ``ANALOG:DESCRIPTIONS``, and a channel
  scale) and a QTM analog TSV export (``<trial>_a.tsv``).
* QTM's force-plate export (``<trial>_f_1.tsv``): header keys (the plate's name, type, corners
  and size among them), a ``SAMPLE TIME Force_X .. COP_Z`` line, forces in N, moments in N m,
  the centre of pressure in mm.
* ``session.toml`` (see :mod:`data_schema.session`).

The ATI ``.cal`` file is written by :func:`ingest.ati_cal.write_ati_cal`. No writer puts the
wall clock into a file: the same arrays give the same bytes.
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import scipy.io
from scipy.spatial.transform import Rotation

from ingest.qtm_force_plate import COLUMNS

_CHUNK = 4096                     # rows formatted at a time
_MAT_HEADER_BYTES = 116           # MAT v5/v7 descriptive text field


def _write_rows(f: io.TextIOBase, table: np.ndarray, fmt: Sequence[str], sep: str,
                newline: str) -> None:
    """Format a float table row by row; NaN cells are written empty."""
    for start in range(0, len(table), _CHUNK):
        buf = io.StringIO()
        np.savetxt(buf, table[start:start + _CHUNK], fmt=list(fmt), delimiter=sep,
                   newline=newline)
        f.write(buf.getvalue().replace("nan", ""))


def _qtm_header(frames: int, rate_hz: float, timestamp: str, cameras: int,
                count_key: str, count: int, data: str) -> list[str]:
    rate = f"{rate_hz:g}"
    return [f"NO_OF_FRAMES\t{frames}", f"NO_OF_CAMERAS\t{cameras}", f"{count_key}\t{count}",
            f"FREQUENCY\t{rate}", "NO_OF_ANALOG\t0", "ANALOG_FREQUENCY\t0", "DESCRIPTION\t--",
            f"TIME_STAMP\t{timestamp}", f"DATA_INCLUDED\t{data}"]


def _frame_time(frames: int, rate_hz: float) -> np.ndarray:
    idx = np.arange(frames, dtype=np.float64)
    return np.column_stack([idx + 1, idx / rate_hz])


def write_qtm_3d(
    path: str | Path, names: Sequence[str], positions: np.ndarray, rate_hz: float,
    timestamp: str, events: Sequence[tuple[str, int, float]] = (), cameras: int = 5,
) -> None:
    """A QTM TSV 3D export of ``positions`` (T, M, 3) in metres; NaN samples are gaps."""
    frames = positions.shape[0]
    lines = _qtm_header(frames, rate_hz, timestamp, cameras, "NO_OF_MARKERS", len(names), "3D")
    lines += [f"EVENT\t{label}\t{frame}\t{time:.3f}" for label, frame, time in events]
    lines.append("MARKER_NAMES\t" + "\t".join(names))
    lines.append("TRAJECTORY_TYPES\t" + "\t".join(["Measured"] * len(names)))
    lines.append("Frame\tTime\t" + "\t".join(f"{n} {a}" for n in names for a in "XYZ") + "\t")
    mm = positions.reshape(frames, -1) * 1e3
    table = np.concatenate([_frame_time(frames, rate_hz), mm], axis=1)
    with open(path, "w", newline="", encoding="utf-8") as f:
        f.write("\r\n".join(lines) + "\r\n")
        _write_rows(f, table, ["%d", "%.5f"] + ["%.3f"] * mm.shape[1], "\t", "\r\n")


def qtm_euler(rotations: np.ndarray) -> np.ndarray:
    """(T, 3) roll, pitch, yaw (deg) of body-to-lab rotations: R = Rx(roll) Ry(pitch) Rz(yaw)."""
    return Rotation.from_matrix(rotations).as_euler("XYZ", degrees=True)


def write_qtm_6d(
    path: str | Path, body: str, positions: np.ndarray, rotations: np.ndarray,
    residuals: np.ndarray, rate_hz: float, timestamp: str,
    events: Sequence[tuple[str, int, float]] = (), cameras: int = 5,
) -> None:
    """A QTM TSV 6D export of one body: origin (T, 3) m, rotations (T, 3, 3) body to lab,
    residuals (T,) m; frames where any of them is NaN are written lost (zeros, residual -1)."""
    frames = positions.shape[0]
    lost = ~(np.isfinite(positions).all(axis=1) & np.isfinite(residuals)
             & np.isfinite(rotations).all(axis=(1, 2)))
    rot = np.where(lost[:, None, None], np.eye(3), rotations)
    values = np.concatenate([
        positions * 1e3, qtm_euler(rot), residuals[:, None] * 1e3,
        rot.transpose(0, 2, 1).reshape(frames, 9),            # column-major Rot[0..8]
    ], axis=1)
    values[lost] = 0.0
    values[lost, 6] = -1.0
    lines = _qtm_header(frames, rate_hz, timestamp, cameras, "NO_OF_BODIES", 1, "6D")
    lines += [f"EVENT\t{label}\t{frame}\t{time:.3f}" for label, frame, time in events]
    lines.append(f"BODY_NAMES\t{body}")
    labels = [f"{body} X", "Y", "Z", "Roll", "Pitch", "Yaw", "Residual",
              *(f"Rot[{k}]" for k in range(9))]
    lines.append("Frame\tTime\t" + "\t".join(labels) + "\t")
    table = np.concatenate([_frame_time(frames, rate_hz), values], axis=1)
    fmt = ["%d", "%.5f"] + ["%.3f"] * 7 + ["%.6f"] * 9
    with open(path, "w", newline="", encoding="utf-8") as f:
        f.write("\r\n".join(lines) + "\r\n")
        _write_rows(f, table, fmt, "\t", "\r\n")


def write_c3d(
    path: str | Path, names: Sequence[str], positions: np.ndarray, rate_hz: float,
    analog: Mapping[str, np.ndarray], analog_hz: float, labels: Sequence[str],
    units: Sequence[str], scale: float,
) -> None:
    """A C3D file of ``positions`` (T, M, 3) in metres (NaN: gap, residual -1) with the
    ``analog`` channels (name -> (T * k,) values, k = analog_hz / rate_hz) named ``labels`` in
    ``ANALOG:LABELS`` and by their full names in ``ANALOG:DESCRIPTIONS``.

    ezc3d stores ``value / (scale * GEN_SCALE) + OFFSET`` and its reader undoes it (the C3D
    standard), so ``scale`` shapes the stored numbers, not the values read back.
    """
    import ezc3d

    frames = positions.shape[0]
    c = ezc3d.c3d()
    point = c["parameters"]["POINT"]
    point["RATE"]["value"] = [rate_hz]
    point["LABELS"]["value"] = list(names)
    point["UNITS"]["value"] = ["mm"]
    gaps = np.isnan(positions).any(axis=2).T                          # (M, T)
    pts = np.ones((4, len(names), frames))
    pts[:3] = np.nan_to_num(positions.transpose(2, 1, 0) * 1e3)
    c["data"]["points"] = pts
    c["data"]["meta_points"] = {"residuals": np.where(gaps, -1.0, 0.0)[None],
                                "camera_masks": np.zeros((7, len(names), frames), bool)}
    group = c["parameters"]["ANALOG"]
    group["RATE"]["value"] = [analog_hz]
    group["LABELS"]["value"] = list(labels)
    group["DESCRIPTIONS"]["value"] = list(analog)
    group["UNITS"]["value"] = list(units)
    group["SCALE"]["value"] = [scale] * len(analog)
    group["OFFSET"]["value"] = [0] * len(analog)
    group["GEN_SCALE"]["value"] = [1.0]
    c["data"]["analogs"] = np.stack([np.asarray(v, float) for v in analog.values()])[None]
    path = Path(path)
    if path.suffix.lower() == ".c3d":
        c.write(str(path))
        return
    written = path.with_name(path.name + ".c3d")        # ezc3d adds .c3d to any other name
    c.write(str(written))
    written.replace(path)


def write_qtm_analog(path: str | Path, analog: Mapping[str, np.ndarray], analog_hz: float,
                     timestamp: str) -> None:
    """A QTM analog TSV export (``<trial>_a.tsv``, FILE_VERSION 2.0.0) of one analog board:
    header keys as QTM's manual lists them, a ``SAMPLE TIME <names>`` line, volts."""
    names = list(analog)
    n = len(next(iter(analog.values())))
    lines = ["FILE_VERSION\t2.0.0", f"TOT_NO_OF_CHAN\t{len(names)}", "NO_OF_CALC_CHAN\t0",
             f"TIME_STAMP\t{timestamp}", "DESCRIPTION\t--", "DATA_INCLUDED\tANALOG",
             "CHANNEL_NAMES\t" + "\t".join(names),
             "CHANNEL_GAIN\t" + "\t".join(["1"] * len(names)),
             "CHANNEL_FREQUENCIES\t" + "\t".join([f"{analog_hz:g}"] * len(names)),
             "CHANNEL_SAMPLE_COUNTS\t" + "\t".join([str(n)] * len(names)),
             "SAMPLE\tTIME\t" + "\t".join(names)]
    idx = np.arange(n, dtype=np.float64)
    table = np.column_stack([idx + 1, idx / analog_hz, *analog.values()])
    with open(path, "w", newline="", encoding="utf-8") as f:
        f.write("\r\n".join(lines) + "\r\n")
        _write_rows(f, table, ["%d", "%.5f"] + ["%.6f"] * len(names), "\t", "\r\n")


def write_qtm_force_plate(path: str | Path, values: np.ndarray, rate_hz: float,
                          timestamp: str, plate: Sequence[tuple[str, str]]) -> None:
    """A QTM force-plate TSV export (``<trial>_f_1.tsv``) of one plate's samples ``values``
    (L, 9: force N, moment N m, centre of pressure mm, in the plate's frame) at ``rate_hz``,
    the samples on the mocap's clock from its first frame; ``plate`` the header keys that
    describe the plate (``FORCE_PLATE_*``), in order."""
    n = len(values)
    lines = [f"NO_OF_SAMPLES\t{n}", f"FREQUENCY\t{rate_hz:g}", f"TIME_STAMP\t{timestamp}",
             "FIRST_SAMPLE\t1", "DESCRIPTION\tForce data in local (force plate) coordinates",
             "DATA_INCLUDED\tForce", *(f"{k}\t{v}" for k, v in plate),
             "SAMPLE\tTIME\t" + "\t".join(COLUMNS)]
    idx = np.arange(n, dtype=np.float64)
    table = np.column_stack([idx + 1, idx / rate_hz, values])
    with open(path, "w", newline="", encoding="utf-8") as f:
        f.write("\r\n".join(lines) + "\r\n")
        _write_rows(f, table, ["%d", "%.5f"] + ["%.6f"] * 6 + ["%.3f"] * 3, "\t", "\r\n")


def write_force_csv(path: str | Path, columns: Mapping[str, np.ndarray],
                    formats: Mapping[str, str]) -> None:
    """A comma-separated log with a header row of column names (no index)."""
    names = list(columns)
    table = np.column_stack([np.asarray(columns[n], dtype=np.float64) for n in names])
    with open(path, "w", newline="", encoding="utf-8") as f:
        f.write(",".join(names) + "\n")
        _write_rows(f, table, [formats[n] for n in names], ",", "\n")


def write_force_mat(path: str | Path, columns: Mapping[str, np.ndarray], header: str) -> None:
    """A MAT v7 (version 5 format) file with one double column vector per signal.

    scipy stamps the creation time into the 116-byte text header; it is replaced by ``header``
    so that the same data give the same bytes.
    """
    scipy.io.savemat(path, {n: np.asarray(v, dtype=np.float64)[:, None]
                            for n, v in columns.items()},
                     format="5", do_compression=True, oned_as="column")
    text = header.encode("ascii")[:_MAT_HEADER_BYTES].ljust(_MAT_HEADER_BYTES, b" ")
    with open(path, "r+b") as f:
        f.write(text)


def _toml_value(v: object) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, Sequence):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def write_session_toml(path: str | Path, top: Mapping[str, object],
                       tables: Mapping[str, Mapping[str, object]]) -> None:
    """``session.toml``: top-level keys, then one ``[table]`` per entry of ``tables`` (a
    value that is itself a mapping: a sub-table ``[table.key]`` after it)."""
    lines = [f"{k} = {_toml_value(v)}" for k, v in top.items()]
    for name, table in tables.items():
        plain = {k: v for k, v in table.items() if not isinstance(v, Mapping)}
        lines += ["", f"[{name}]"] + [f"{k} = {_toml_value(v)}" for k, v in plain.items()]
        for key, sub in table.items():
            if isinstance(sub, Mapping):
                lines += ["", f"[{name}.{key}]"] + [f"{k} = {_toml_value(v)}"
                                                    for k, v in sub.items()]
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")

"""ATI force/torque calibration files (``FT12345.cal``, XML).

ATI's own note in every file: build the calibration matrix from the six ``UserAxis`` rows (Fx,
Fy, Fz, Tx, Ty, Tz); the ``Axis`` rows are scaled for ATI's internal use. Rows are converted to
SI (N and N*m per volt) from the file's ``ForceUnits`` / ``TorqueUnits``, and so are the rated
loads (``max``). ``write_ati_cal`` writes the inverse, in N and N-mm as ATI ships Nano17 files.
Units come from :mod:`core.units` (``unit_to_si`` is re-exported here for callers).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from core.atomic import atomic_output
from core.errors import BadInput
from core.series import AtiCalibration
from core.units import unit_to_si

AXES = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")


def _floats(text: str | None, path: str | Path, what: str) -> np.ndarray:
    try:
        return np.array([float(v) for v in (text or "").split()], dtype=np.float64)
    except ValueError:
        raise BadInput(path, f"{what} is not a list of numbers: {text!r}") from None


def _scale(path: str | Path, key: str, unit: str, si: str, what: str) -> float:
    """SI factor of the file's force or torque unit; a unit of another kind is bad input."""
    try:
        factor, got = unit_to_si(unit)
    except ValueError as e:
        raise BadInput(path, f"Calibration {key}: {e}") from None
    if got != si:
        raise BadInput(path, f"Calibration {key} {unit!r} is not a {what} unit")
    return factor


def read_ati_cal(path: str | Path) -> AtiCalibration:
    """Read an ATI .cal file: the 6x6 ``UserAxis`` matrix and rated loads, in SI units.

    Every row has six finite numbers and the units are a force and a torque unit, so the
    matrix it returns is always a finite 6x6.
    """
    try:
        root = ET.parse(path).getroot()
    except FileNotFoundError:
        raise BadInput(path, "no such file") from None
    except (ET.ParseError, OSError) as e:
        raise BadInput(path, f"not a readable ATI calibration XML ({e})") from None
    if root.tag != "FTSensor":
        raise BadInput(path, f"not an ATI calibration file (root element <{root.tag}>)")
    cal = root.find("Calibration")
    if cal is None:
        raise BadInput(path, "no <Calibration> element")
    rows: dict[str, tuple[np.ndarray, float]] = {}
    for axis in cal.findall("UserAxis"):
        name = axis.get("Name", "")
        if name not in AXES:
            raise BadInput(path, f"UserAxis Name {name!r} is not one of {', '.join(AXES)}")
        if name in rows:
            raise BadInput(path, f"UserAxis {name} appears twice")
        values = _floats(axis.get("values"), path, f"UserAxis {name} values")
        if values.size != 6:
            raise BadInput(path, f"UserAxis {name} has {values.size} values, expected 6 "
                                 "(one per gauge)")
        rated = _floats(axis.get("max", "nan"), path, f"UserAxis {name} max")
        rows[name] = (values, float(rated[0]) if rated.size == 1 else float("nan"))
    absent = [a for a in AXES if a not in rows]
    if absent:
        raise BadInput(path, f"calibration is not 6x6: no UserAxis row for {', '.join(absent)}")
    force_units = cal.get("ForceUnits", "N")
    torque_units = cal.get("TorqueUnits", "N-mm")
    f_scale = _scale(path, "ForceUnits", force_units, "N", "force")
    t_scale = _scale(path, "TorqueUnits", torque_units, "N*m", "torque")
    scale = np.array([f_scale] * 3 + [t_scale] * 3)
    for a in AXES:
        if not np.isfinite(rows[a][0]).all():
            raise BadInput(path, f"UserAxis {a} has a non-finite value: {rows[a][0].tolist()}")
    matrix = np.array([rows[a][0] for a in AXES]) * scale[:, None]
    max_load = np.array([rows[a][1] for a in AXES]) * scale
    meta: dict[str, Any] = {
        "sensor": dict(root.attrib),
        "calibration": dict(cal.attrib),
    }
    transform = cal.find("BasicTransform")
    if transform is not None:
        meta["basic_transform"] = dict(transform.attrib)
    return AtiCalibration(
        source=str(path), serial=root.get("Serial", ""), body_style=root.get("BodyStyle", ""),
        calibration=cal.get("PartNumber", ""), matrix=matrix, max_load=max_load,
        force_units=force_units, torque_units=torque_units, meta=meta,
    )


def _values(row: np.ndarray) -> str:
    """ATI's layout of a row: each number in 9 characters with 5 decimals, space-separated."""
    return "".join(f"{v:9.5f} " for v in row)


def write_ati_cal(path: str | Path, calibration: AtiCalibration) -> None:
    """Write ``calibration`` as an ATI .cal XML file (forces in N, torques in N-mm)."""
    if calibration.matrix.shape != (6, 6) or calibration.max_load.shape != (6,):
        raise ValueError("calibration matrix must be 6x6 and max_load 6 values")
    scale = np.array([1.0] * 3 + [1e3] * 3)                         # N*m -> N-mm
    matrix = calibration.matrix * scale[:, None]
    rated = calibration.max_load * scale
    sensor = {"Serial": calibration.serial, "BodyStyle": calibration.body_style,
              "Family": "DAQ", "NumGages": "6", "CalFileVersion": "1.1"}
    sensor.update({k: v for k, v in calibration.meta.get("sensor", {}).items() if k not in sensor})
    cal = {**calibration.meta.get("calibration", {}), "PartNumber": calibration.calibration,
           "ForceUnits": "N", "TorqueUnits": "N-mm", "DistUnits": "mm"}

    def attrs(d: dict[str, Any]) -> str:
        return "".join(f"  {k}={quoteattr(str(v))}" for k, v in d.items())

    lines = [
        '<?xml version="1.0" encoding="utf-8"?>',
        "<!-- Build the calibration matrix from the UserAxis rows (Fx, Fy, Fz, Tx, Ty, Tz). -->",
        f"<FTSensor{attrs(sensor)}>",
        f"\t<Calibration{attrs(cal)}>",
    ]
    transform = calibration.meta.get("basic_transform")
    if transform:
        lines.append(f"\t\t<BasicTransform{attrs(transform).replace('  ', ' ')}/>")
    for axis, row, top in zip(AXES, matrix, rated, strict=True):
        lines.append(f'\t\t<UserAxis Name="{axis}" values="{_values(row)}" max="{top:g}"/>')
    lines += ["\t</Calibration>", "</FTSensor>", ""]
    with atomic_output(path) as tmp:
        Path(tmp).write_text("\n".join(lines), encoding="utf-8")

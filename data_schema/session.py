"""``session.toml``: which lab file is which in a session folder.

Example (every path relative to the folder)::

    schema = "phantom.session"
    schema_version = "1.0"
    name = "phantom-2026-11-21"

    [mocap]
    file = "trial_3d.tsv"              # QTM TSV 3D, C3D or QTM MAT (format found from content)
    bodies_file = "trial_6d.tsv"       # optional: QTM TSV 6D with the indenter rigid body
    phantom_markers = ["P00", "P01", ...]   # the 25 surface markers
    indenter_markers = ["I1", "I2", "I3", "I4"]
    indenter_body = "Indenter"         # optional: body name in the 6D file
    trigger_event = "Trigger"          # optional: EVENT label of the sync pulses in the TSV

    [force]
    file = "force.csv"                 # CSV, MAT (v7 or v7.3) or Parquet
    time_column = "time"
    time_unit = "s"                    # s | ms | us | ns
    kind = "gauge"                     # gauge: six volts + calibration; wrench: Fx..Tz
    channels = ["G0", "G1", "G2", "G3", "G4", "G5"]
    units = "V"                        # gauge: V; wrench: "N,N,N,N*m,N*m,N*m" style list
    calibration = "FT12345.cal"        # ATI .cal XML; required for kind = "gauge"
    trigger_column = "trigger"         # optional sync/trigger channel

    [pivot]
    file = "pivot_3d.tsv"              # optional: pivot recording for the tip offset
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from pipeline.errors import BadInput

SCHEMA = "phantom.session"
VERSION = "1.0"
TIME_UNITS = {"s": 1e9, "ms": 1e6, "us": 1e3, "ns": 1.0}


@dataclass(frozen=True)
class MocapConfig:
    file: Path
    phantom_markers: list[str]
    indenter_markers: list[str]
    bodies_file: Path | None = None
    indenter_body: str | None = None
    trigger_event: str | None = None


@dataclass(frozen=True)
class ForceConfig:
    file: Path
    time_column: str
    time_unit: str
    kind: str
    channels: list[str]
    units: list[str]
    calibration: Path | None = None
    trigger_column: str | None = None


@dataclass(frozen=True)
class SessionConfig:
    folder: Path
    name: str
    mocap: MocapConfig
    force: ForceConfig
    pivot_file: Path | None = None
    raw: dict = field(default_factory=dict)


def read_session(folder: str | Path) -> SessionConfig:
    """Parse and check ``folder/session.toml``; every file it names must exist."""
    folder = Path(folder)
    path = folder / "session.toml"
    if not path.is_file():
        raise BadInput(folder, "no session.toml in this folder")
    try:
        raw = tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise BadInput(path, f"not valid TOML ({e})") from None
    if raw.get("schema", SCHEMA) != SCHEMA:
        raise BadInput(path, f"schema is {raw.get('schema')!r}, expected {SCHEMA!r}")
    mocap = _mocap(path, folder, _table(path, raw, "mocap"))
    force = _force(path, folder, _table(path, raw, "force"))
    pivot = raw.get("pivot", {}).get("file")
    return SessionConfig(
        folder=folder, name=str(raw.get("name", folder.name)), mocap=mocap, force=force,
        pivot_file=_file(path, folder, pivot, "pivot.file") if pivot else None, raw=raw,
    )


def _mocap(path: Path, folder: Path, t: dict) -> MocapConfig:
    phantom = _names(path, t, "phantom_markers")
    indenter = _names(path, t, "indenter_markers")
    dup = set(phantom) & set(indenter)
    if dup:
        raise BadInput(path, f"marker(s) listed as both phantom and indenter: {sorted(dup)}")
    bodies = t.get("bodies_file")
    return MocapConfig(
        file=_file(path, folder, t.get("file"), "mocap.file"),
        phantom_markers=phantom, indenter_markers=indenter,
        bodies_file=_file(path, folder, bodies, "mocap.bodies_file") if bodies else None,
        indenter_body=t.get("indenter_body"), trigger_event=t.get("trigger_event"),
    )


def _force(path: Path, folder: Path, t: dict) -> ForceConfig:
    kind = t.get("kind", "gauge")
    if kind not in ("gauge", "wrench"):
        raise BadInput(path, f"force.kind must be 'gauge' or 'wrench', got {kind!r}")
    unit = t.get("time_unit", "s")
    if unit not in TIME_UNITS:
        raise BadInput(path, f"force.time_unit must be one of {sorted(TIME_UNITS)}, got {unit!r}")
    channels = _names(path, t, "channels")
    if len(channels) != 6:
        raise BadInput(path, f"force.channels must name 6 columns, got {len(channels)}")
    units = t.get("units", "V" if kind == "gauge" else "N,N,N,N*m,N*m,N*m")
    units = [u.strip() for u in units.split(",")] if isinstance(units, str) else list(units)
    if len(units) == 1:
        units = units * 6
    cal = t.get("calibration")
    if kind == "gauge" and not cal:
        raise BadInput(path, "force.kind = 'gauge' needs force.calibration (an ATI .cal file)")
    return ForceConfig(
        file=_file(path, folder, t.get("file"), "force.file"),
        time_column=str(t.get("time_column", "time")), time_unit=unit, kind=kind,
        channels=channels, units=units,
        calibration=_file(path, folder, cal, "force.calibration") if cal else None,
        trigger_column=t.get("trigger_column"),
    )


def _table(path: Path, raw: dict, key: str) -> dict:
    t = raw.get(key)
    if not isinstance(t, dict):
        raise BadInput(path, f"missing [{key}] table")
    return t


def _names(path: Path, t: dict, key: str) -> list[str]:
    v = t.get(key)
    if not isinstance(v, list) or not v or not all(isinstance(x, str) for x in v):
        raise BadInput(path, f"{key} must be a non-empty list of names")
    if len(set(v)) != len(v):
        raise BadInput(path, f"{key} has duplicate names")
    return list(v)


def _file(path: Path, folder: Path, name: object, key: str) -> Path:
    if not isinstance(name, str) or not name:
        raise BadInput(path, f"{key} must name a file")
    f = folder / name
    if not f.is_file():
        raise BadInput(path, f"{key} = {name!r}: no such file")
    return f

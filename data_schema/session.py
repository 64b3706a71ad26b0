"""``session.toml``: which lab file is which in a session folder.

Example (every path relative to the folder)::

    schema = "phantom.session"
    schema_version = "1.0"
    name = "phantom-2026-11-21"

    [mocap]
    file = "trial_3d.tsv"              # QTM TSV 3D, C3D or QTM MAT (format found from content)
    bodies_file = "trial_6d.tsv"       # optional: QTM TSV 6D with the indenter rigid body
    phantom_markers = ["P00", "P01", ...]   # the phantom's surface markers (4 or more)
    indenter_markers = ["I1", "I2", "I3", "I4"]
    indenter_body = "Indenter"         # optional: body name in the 6D file
    trigger_event = "Trigger"          # optional: EVENT label of the sync pulses in the TSV

    [force]
    file = "force.csv"                 # a force log: CSV/TXT in any dialect, ATI DAQ F/T or
                                       # Net F/T CSV, QTM force-plate TSV, MAT (v7 or v7.3),
                                       # Parquet; or the mocap system's analog channels: C3D
                                       # or QTM analog TSV (format found from content)
    time_column = "time"               # force logs: the time column (default: "time", else
                                       # the layout's own time: MAT arrays/structs, Net F/T,
                                       # QTM; analog samples are timed by the rate)
    time_unit = "s"                    # s | ms | us | ns (default: the unit the column's
                                       # name states, "time (ms)", "t_ms"; else s)
    kind = "gauge"                     # gauge: six volts + calibration; wrench: Fx..Tz
    channels = ["G0", "G1", "G2", "G3", "G4", "G5"]   # names, or 1-based numbers: analog
                                       # channel numbers; in a log, signal numbers counted
                                       # without the time column (unnamed MAT/CSV signals)
    units = "V"                        # gauge: V; wrench: "N,N,N,N*m,N*m,N*m" style list;
                                       # default: what the file states (column names, Net F/T
                                       # preamble, QTM, C3D ANALOG:UNITS), else V / N and N*m
    rate_hz = 1000.0                   # optional: analog: the rate (checked); a log without a
                                       # time column (ATI DAQ F/T without Frequency): its rate
    variable = "force_log.signals.values"   # optional, MAT: the variable or struct field
                                       # where the file holds several logs
    delimiter = ";"                    # optional, text: , ; tab | space, where sniffing
    decimal = ","                      # cannot decide; decimal mark . or ,
    scale = [500, 500, 1000, 40, 40, 20]   # optional, per channel (or one for all): volts
    offset = [0.002, 0, 0, 0, 0, 0]    # into `units`: (value - offset) x scale (N/V, N m/V);
                                       # a value in mV is taken to V first
    calibration = "FT12345.cal"        # ATI .cal XML; required for kind = "gauge"
    trigger_column = "trigger"         # optional sync/trigger channel (name or number)

    [pivot]
    file = "pivot_3d.tsv"              # optional: pivot recording for the tip offset

    [phantom]                          # optional: the footprint and how the markers lie on
    size_mm = [100.0, 100.0]           # it (data_schema/phantom.py says every key)
"""

from __future__ import annotations

import tomllib
from collections.abc import Collection
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, overload

from core.errors import BadInput
from core.units import TIME_UNITS, channel_units
from data_schema.phantom import PhantomLayout, read_layout

SCHEMA = "phantom.session"
# force.delimiter's spellings -> the character (" ": any run of spaces or tabs)
DELIMITERS = {",": ",", ";": ";", "\t": "\t", "tab": "\t", "|": "|", " ": " ",
              "space": " ", "whitespace": " "}
VERSION = "1.0"


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
    channels: list[str | int]      # column names; analog channels also by 1-based number
    units: list[str]
    calibration: Path | None = None
    trigger_column: str | int | None = None
    rate_hz: float | None = None   # analog: the rate (checked); a log without time: its rate
    variable: str | None = None    # MAT: the variable or struct path ("x.signals.values")
    delimiter: str | None = None   # text: the delimiter where sniffing cannot decide
    decimal: str | None = None     # text: the decimal mark ("." or ",")
    scale: list[float] | None = None    # per channel: (value - offset) x scale, in `units`
    offset: list[float] | None = None
    stated: frozenset[str] = frozenset()   # the [force] keys session.toml states


@dataclass(frozen=True)
class SessionConfig:
    folder: Path
    name: str
    mocap: MocapConfig
    force: ForceConfig
    pivot_file: Path | None = None
    phantom: PhantomLayout = field(default_factory=PhantomLayout)
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
    schema = _str(path, raw, "schema", SCHEMA)
    if schema != SCHEMA:
        raise BadInput(path, f"schema is {schema!r}, expected {SCHEMA!r}")
    version = _str(path, raw, "schema_version", VERSION)
    if version.split(".")[0] != VERSION.split(".")[0]:
        raise BadInput(path, f"schema_version {version!r} is not compatible with {VERSION}")
    mocap = _mocap(path, folder, _table(path, raw, "mocap"))
    force = _force(path, folder, _table(path, raw, "force"))
    pivot = _table(path, raw, "pivot", required=False)
    return SessionConfig(
        folder=folder, name=_str(path, raw, "name", folder.name), mocap=mocap, force=force,
        pivot_file=_file(path, folder, pivot, "file", "pivot") if pivot else None,
        phantom=read_layout(path, _table(path, raw, "phantom", required=False),
                            mocap.phantom_markers), raw=raw,
    )


def _mocap(path: Path, folder: Path, t: dict) -> MocapConfig:
    phantom = _names(path, t, "phantom_markers")
    indenter = _names(path, t, "indenter_markers")
    dup = set(phantom) & set(indenter)
    if dup:
        raise BadInput(path, f"marker(s) listed as both phantom and indenter: {sorted(dup)}")
    return MocapConfig(
        file=_file(path, folder, t, "file", "mocap"),
        phantom_markers=phantom, indenter_markers=indenter,
        bodies_file=_file(path, folder, t, "bodies_file", "mocap", required=False),
        indenter_body=_str(path, t, "indenter_body", table="mocap"),
        trigger_event=_str(path, t, "trigger_event", table="mocap"),
    )


def _force(path: Path, folder: Path, t: dict) -> ForceConfig:
    kind = _str(path, t, "kind", "gauge", table="force")
    if kind not in ("gauge", "wrench"):
        raise BadInput(path, f"force.kind must be 'gauge' or 'wrench', got {kind!r}")
    unit = _str(path, t, "time_unit", "s", table="force")
    if unit not in TIME_UNITS:
        raise BadInput(path, f"force.time_unit must be one of {', '.join(TIME_UNITS)}, "
                             f"got {unit!r}")
    channels = _channels(path, t.get("channels"), "force.channels")
    if len(channels) != 6:
        raise BadInput(path, f"force.channels must name 6 columns, got {len(channels)}")
    try:
        units = channel_units(t.get("units"), kind, len(channels))
    except ValueError as e:
        raise BadInput(path, f"force.units: {e}") from None
    cal = _file(path, folder, t, "calibration", "force", required=False)
    if kind == "gauge" and cal is None:
        raise BadInput(path, "force.kind = 'gauge' needs force.calibration (an ATI .cal file)")
    return ForceConfig(
        file=_file(path, folder, t, "file", "force"),
        time_column=_str(path, t, "time_column", "time", table="force"), time_unit=unit,
        kind=kind, channels=channels, units=units, calibration=cal,
        trigger_column=None if t.get("trigger_column") is None else
        _channel(path, t["trigger_column"], "force.trigger_column"),
        rate_hz=_rate(path, t.get("rate_hz")),
        variable=_str(path, t, "variable", table="force"),
        delimiter=_choice(path, t, "delimiter", DELIMITERS),
        decimal=_choice(path, t, "decimal", (".", ",")),
        scale=_numbers6(path, t, "scale", len(channels)),
        offset=_numbers6(path, t, "offset", len(channels)),
        stated=frozenset(t),
    )


def _choice(path: Path, t: dict, key: str, allowed: Collection[str]) -> str | None:
    """force.<key>: absent, or one of ``allowed``."""
    v = t.get(key)
    if v is None:
        return None
    if not isinstance(v, str) or v not in allowed:
        raise BadInput(path, f"force.{key} must be one of "
                             f"{', '.join(repr(a) for a in allowed)}, got {v!r}")
    return DELIMITERS.get(v, v) if key == "delimiter" else v


def _numbers6(path: Path, t: dict, key: str, n: int) -> list[float] | None:
    """force.scale / force.offset: absent, one number for every channel, or one per channel."""
    v = t.get(key)
    if v is None:
        return None
    items = v if isinstance(v, list) else [v]
    if len(items) not in (1, n) or not all(
            isinstance(x, int | float) and not isinstance(x, bool) and abs(x) < float("inf")
            for x in items):
        raise BadInput(path, f"force.{key} must be a number or {n} numbers (one per "
                             f"channel), got {v!r}")
    if key == "scale" and any(x == 0 for x in items):
        raise BadInput(path, "force.scale must not be 0")
    return [float(x) for x in items] * (n if len(items) == 1 else 1)


def _channels(path: Path, v: object, name: str) -> list[str | int]:
    """Channel names, or (analog channels) 1-based channel numbers; distinct."""
    if not isinstance(v, list) or not v:
        raise BadInput(path, f"{name} must be a non-empty list of names or channel numbers "
                             f"(1, 2, ...), got {v!r}")
    out = [_channel(path, x, name) for x in v]
    if len(set(out)) != len(out):
        raise BadInput(path, f"{name} has duplicate entries")
    return out


def _channel(path: Path, v: object, name: str) -> str | int:
    """A channel name (non-empty text) or 1-based channel number."""
    if (isinstance(v, str) and v.strip()) or (type(v) is int and v >= 1):
        return v
    raise BadInput(path, f"{name} must name channels by name (non-empty text) or number "
                         f"(1, 2, ...), got {v!r}")


def _rate(path: Path, v: object) -> float | None:
    """force.rate_hz: absent, or a number > 0."""
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, int | float) or not v > 0 or v == float("inf"):
        raise BadInput(path, f"force.rate_hz must be a rate in Hz (a number > 0), got {v!r}")
    return float(v)


@overload
def _table(path: Path, raw: dict, key: str, required: Literal[True] = True) -> dict: ...
@overload
def _table(path: Path, raw: dict, key: str, required: bool) -> dict | None: ...
def _table(path: Path, raw: dict, key: str, required: bool = True) -> dict | None:
    """The ``[key]`` table; None when it is optional and absent."""
    t = raw.get(key)
    if t is None and not required:
        return None
    if not isinstance(t, dict):
        raise BadInput(path, f"missing [{key}] table" if t is None else
                             f"{key} must be a [{key}] table, got {t!r}")
    return t


@overload
def _str(path: Path, t: dict, key: str, default: str, table: str | None = None) -> str: ...
@overload
def _str(path: Path, t: dict, key: str, default: None = None,
         table: str | None = None) -> str | None: ...
def _str(path: Path, t: dict, key: str, default: str | None = None,
         table: str | None = None) -> str | None:
    """An optional text value (``default`` when absent); anything but non-empty text is bad."""
    v = t.get(key, default)
    if v is not None and (not isinstance(v, str) or not v.strip()):
        name = f"{table}.{key}" if table else key
        raise BadInput(path, f"{name} must be a non-empty string, got {v!r}")
    return v


def _names(path: Path, t: dict, key: str, table: str = "mocap") -> list[str]:
    v = t.get(key)
    if not isinstance(v, list) or not v or not all(isinstance(x, str) and x for x in v):
        raise BadInput(path, f"{table}.{key} must be a non-empty list of names")
    if len(set(v)) != len(v):
        raise BadInput(path, f"{table}.{key} has duplicate names")
    return list(v)


@overload
def _file(path: Path, folder: Path, t: dict, key: str, table: str,
          required: Literal[True] = True) -> Path: ...
@overload
def _file(path: Path, folder: Path, t: dict, key: str, table: str,
          required: bool) -> Path | None: ...
def _file(path: Path, folder: Path, t: dict, key: str, table: str,
          required: bool = True) -> Path | None:
    """The file ``t[key]`` names, relative to the folder; it must exist."""
    name = _str(path, t, key, table=table)
    if name is None:
        if required:
            raise BadInput(path, f"{table}.{key} must name a file")
        return None
    f = folder / name
    if not f.is_file():
        raise BadInput(path, f"{table}.{key} = {name!r}: no such file")
    return f

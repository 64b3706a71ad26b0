"""The force of a session, from wherever session.toml's ``[force]`` table says: a force log
(:func:`ingest.force_log.read_force_log`, any layout, a QTM force-plate export among them) or
the mocap system's analog channels (:func:`ingest.analog.analog_force`: C3D, QTM analog TSV),
with the keys it states."""

from __future__ import annotations

from core.errors import BadInput
from core.series import ForceSeries
from data_schema.session import ForceConfig
from ingest.analog import analog_force
from ingest.detect import ANALOG_FORMATS, detect_format, read_analog
from ingest.force_log import read_force_log
from ingest.log_table import LogTable

_LOG_ONLY = ("variable", "delimiter", "decimal", "time_column", "time_unit")


def read_force(f: ForceConfig) -> ForceSeries:
    """The force channels the config names, in SI units."""
    units = f.units if "units" in f.stated else None
    if detect_format(f.file) in ANALOG_FORMATS:
        extra = [k for k in _LOG_ONLY if k in f.stated]
        if extra:
            raise BadInput(f.file, f"force.{extra[0]} is for force logs; {f.file.name} is an "
                                   "analog export (channels by name or number, timed by its "
                                   "rate)")
        return analog_force(read_analog(f.file), f.channels, f.kind, f.rate_hz,
                            f.trigger_column, units=units, scale=f.scale, offset=f.offset)
    return log_force(f)


def log_force(f: ForceConfig, table: LogTable | None = None, source: str | None = None
              ) -> ForceSeries:
    """The force log's channels the config names, in SI units: the file's, or ``table``'s
    (the log's columns read elsewhere: a force plate's samples off QTM's real-time stream,
    ``source`` naming the server in a refusal), with the same keys and checks."""
    return read_force_log(source or f.file, f.time_column, list(f.channels),
                          time_unit=f.time_unit if "time_unit" in f.stated else None,
                          units=f.units if "units" in f.stated else None, kind=f.kind,
                          trigger_column=f.trigger_column, variable=f.variable,
                          delimiter=f.delimiter, decimal=f.decimal, rate_hz=f.rate_hz,
                          scale=f.scale, offset=f.offset, table=table)

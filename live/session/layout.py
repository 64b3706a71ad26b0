"""A live capture held against its session: which of QTM's markers, and which analog board or
force plate, are the session's, checked with ingest's rules and messages before the first frame
is read.

``session.toml`` names the phantom and indenter markers and the force's six channels (by name
or 1-based number), their kind (gauge volts or a wrench), units, scale and offset, exactly as
for an exported session. QTM's parameters must carry every named marker. Where the session's
force file is a QTM force-plate export, the force streams as QTM's force component: the plate
the export names (``FORCE_PLATE_NAME``; any plate where it names none) must be among QTM's, at
the stated rate and in units that agree with the session's, checked as ingest checks the export
(:func:`ingest.force_source.log_force`). Otherwise one analog board must carry the six channels
so: the checks ingest makes on an analog export (:func:`ingest.analog.analog_force`). So a live
session is refused where its export would be, with the same words.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core.errors import BadInput
from core.series import AtiCalibration, ForceSeries
from data_schema.session import SessionConfig
from ingest.analog import AnalogExport, analog_force
from ingest.ati_cal import read_ati_cal
from ingest.detect import detect_format
from ingest.force_source import log_force
from ingest.log_table import LogTable
from ingest.qtm_force_plate import export_plate_name
from live.protocol.parameters import ForceDevice, ForcePlate, QtmParameters

FORMAT = "qtm_rt"                 # the analog export's format, as ingest's readers name theirs
PLATE_FORMAT = "qtm_rt_force"     # a plate's samples as a force log, as ingest's name theirs
PLATE_EXPORT = "qtm_tsv_force"    # ingest's name of a QTM force-plate export


@dataclass(frozen=True)
class LiveLayout:
    """Where the session's streams are in QTM's frames."""

    source: str                       # the server, "QTM RT host:port"
    rate_hz: float                    # markers
    labels: list[str]                 # every 3D label, in the order QTM sends them
    device: ForceDevice               # the board or plate that samples the force
    calibration: AtiCalibration | None

    def analog_export(self, values: np.ndarray) -> AnalogExport:
        """The board's samples (T, C), in the units QTM states, as ingest's analog export."""
        d, n = self.device, len(self.device.labels)
        return AnalogExport(source=self.source, format=FORMAT, labels=list(d.labels),
                            descriptions=[""] * n, units=list(d.units), scales=np.ones(n),
                            offsets=np.zeros(n), gen_scale=1.0, rate_hz=d.rate_hz,
                            values=values, point_rate_hz=self.rate_hz,
                            meta={"device": d.name, "device_id": d.device_id})

    def plate_table(self, values: np.ndarray) -> LogTable:
        """The plate's samples (T, 9), in the units QTM states, as the columns ingest reads
        from its export: timed by the plate's rate on the mocap's clock (the device a
        :class:`~live.protocol.parameters.ForcePlate`)."""
        d = self.device
        if not isinstance(d, ForcePlate):
            raise ValueError(f"{d.name} is an analog board, not a force plate")
        return LogTable(format=PLATE_FORMAT,
                        columns={c: values[:, i] for i, c in enumerate(d.labels)},
                        units=dict(zip(d.labels, d.units, strict=True)), rate_hz=d.rate_hz,
                        details={"clock": "mocap", "plate": d.name,
                                 "plate_type": d.type, "plate_corners_mm": d.corners_mm})


@dataclass(frozen=True)
class SiMap:
    """The session's force channels in SI units from a device's samples ``v`` (n, C):
    ``offset + v[:, used] @ matrix``, the conversion :func:`to_force` makes, measured once
    (ingest's conversions are affine per channel), so a frame costs a product, not a parse."""

    offset: np.ndarray                # (K,)
    used: np.ndarray                  # the device channels the session reads
    matrix: np.ndarray                # (len(used), K)

    def __call__(self, v: np.ndarray) -> np.ndarray:
        return self.offset + v[:, self.used] @ self.matrix


def live_layout(params: QtmParameters, cfg: SessionConfig) -> LiveLayout:
    """The session's markers and force in QTM's capture; bad input, in ingest's words, where
    QTM lacks a marker or no board (plate) carries the force as session.toml states it."""
    names = cfg.mocap.phantom_markers + cfg.mocap.indenter_markers
    absent = [n for n in names if n not in params.labels]
    if absent:
        raise BadInput(params.source, f"marker(s) named in session.toml not in file: "
                                      f"{', '.join(absent)}")
    plate = detect_format(cfg.force.file) == PLATE_EXPORT
    devices = _plates(params, cfg) if plate else params.analog
    what = "force plate" if plate else "analog board"
    if not devices:
        raise BadInput(params.source, f"no {what} in its parameters: the force session.toml "
                                      "names is not streamed")
    calibration = read_ati_cal(cfg.force.calibration) if cfg.force.calibration else None
    refusals = []
    for device in devices:
        layout = LiveLayout(params.source, params.rate_hz, list(params.labels), device,
                            calibration)
        try:
            to_force(layout, np.zeros((2, len(device.labels))), cfg)
        except BadInput as e:
            refusals.append(e)
            continue
        return layout
    if len(refusals) == 1:
        raise refusals[0]
    raise BadInput(params.source, f"no {what} carries the force session.toml names: "
                   + "; ".join(f"{d.name}: {e.what}" for d, e in
                               zip(devices, refusals, strict=True)))


def _plates(params: QtmParameters, cfg: SessionConfig) -> list[ForceDevice]:
    """QTM's plates that may be the export's: the one its name names (every plate where the
    export names none); bad input where QTM has plates but not that one."""
    name = export_plate_name(cfg.force.file)
    if name is None or not params.plates:
        return list(params.plates)
    named: list[ForceDevice] = [p for p in params.plates if p.name == name]
    if not named:
        raise BadInput(params.source, f"no force plate named {name!r} (the plate of "
                                      f"{cfg.force.file.name}) in its parameters; it has: "
                                      f"{', '.join(p.name for p in params.plates)}")
    return named


def to_force(layout: LiveLayout, values: np.ndarray, cfg: SessionConfig) -> ForceSeries:
    """The device's samples (T, C) as the session's force in SI units on the mocap's clock,
    converted exactly as ingest converts an analog export or a force-plate export."""
    f = cfg.force
    if layout.device.component == "force":
        return log_force(f, layout.plate_table(values), layout.source)
    return analog_force(layout.analog_export(values), f.channels, f.kind, f.rate_hz,
                        f.trigger_column, f.units, f.scale, f.offset)


def si_map(layout: LiveLayout, cfg: SessionConfig) -> SiMap:
    """:class:`SiMap` of the layout's device: :func:`to_force` of a zero sample and of a
    unit sample per channel."""
    c = len(layout.device.labels)
    si = to_force(layout, np.vstack([np.zeros(c), np.eye(c)]), cfg).values
    matrix = si[1:] - si[0]
    used = np.flatnonzero(np.any(matrix != 0, axis=1))
    return SiMap(si[0], used, matrix[used])

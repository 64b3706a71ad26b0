"""A live capture held against its session: which of QTM's markers and analog channels are the
session's, checked with ingest's rules and messages before the first frame is read.

``session.toml`` names the phantom and indenter markers and the force's six channels (by name
or 1-based number), their kind (gauge volts or a wrench), units, scale and offset, exactly as
for an exported session. QTM's parameters must carry every named marker, and one analog board
must carry the six channels at the stated rate and in units that agree with the session's: the
same checks ingest makes on an analog export (:func:`ingest.analog.analog_force`), so a live
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
from live.qtm_parameters import AnalogDevice, QtmParameters

FORMAT = "qtm_rt"                 # the analog export's format, as ingest's readers name theirs


@dataclass(frozen=True)
class LiveLayout:
    """Where the session's streams are in QTM's frames."""

    source: str                       # the server, "QTM RT host:port"
    rate_hz: float                    # markers
    labels: list[str]                 # every 3D label, in the order QTM sends them
    device: AnalogDevice              # the board that samples the force
    calibration: AtiCalibration | None

    def analog_export(self, values: np.ndarray) -> AnalogExport:
        """The board's samples (T, C), in the units QTM states, as ingest's analog export."""
        d, n = self.device, len(self.device.labels)
        return AnalogExport(source=self.source, format=FORMAT, labels=list(d.labels),
                            descriptions=[""] * n, units=list(d.units), scales=np.ones(n),
                            offsets=np.zeros(n), gen_scale=1.0, rate_hz=d.rate_hz,
                            values=values, point_rate_hz=self.rate_hz,
                            meta={"device": d.name, "device_id": d.device_id})


def live_layout(params: QtmParameters, cfg: SessionConfig) -> LiveLayout:
    """The session's markers and force in QTM's capture; bad input, in ingest's words, where
    QTM lacks a marker or no board carries the force as session.toml states it."""
    names = cfg.mocap.phantom_markers + cfg.mocap.indenter_markers
    absent = [n for n in names if n not in params.labels]
    if absent:
        raise BadInput(params.source, f"marker(s) named in session.toml not in file: "
                                      f"{', '.join(absent)}")
    if not params.analog:
        raise BadInput(params.source, "no analog board in its parameters: the force "
                                      "session.toml names is not streamed")
    calibration = read_ati_cal(cfg.force.calibration) if cfg.force.calibration else None
    refusals = []
    for device in params.analog:
        layout = LiveLayout(params.source, params.rate_hz, list(params.labels), device,
                            calibration)
        try:
            to_force(layout, np.empty((0, len(device.labels))), cfg)
        except BadInput as e:
            refusals.append(e)
            continue
        return layout
    if len(refusals) == 1:
        raise refusals[0]
    raise BadInput(params.source, "no analog board carries the force session.toml names: "
                   + "; ".join(f"{d.name}: {e.what}" for d, e in
                               zip(params.analog, refusals, strict=True)))


def to_force(layout: LiveLayout, values: np.ndarray, cfg: SessionConfig) -> ForceSeries:
    """The board's samples (T, C) as the session's force in SI units on the mocap's clock,
    converted exactly as ingest converts an analog export."""
    f = cfg.force
    return analog_force(layout.analog_export(values), f.channels, f.kind, f.rate_hz,
                        f.trigger_column, f.units, f.scale, f.offset)

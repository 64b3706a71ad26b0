"""The twin's session folder, file by file: names, what each file holds, its session.toml.

Session folder::

    session.toml          which file is which (data_schema.session)
    indentation.tsv       QTM TSV 3D at the mocap rate (500 Hz by default), the N phantom markers
                          (P00, P01, ...; 25 by default) + 4 indenter markers, EVENT Trigger lines
    indentation_6D.tsv    QTM TSV 6D of the body "Indenter"
    pivot.tsv             QTM TSV 3D of the 4 indenter markers, tip held in a divot
    force.csv, force.mat  the Speedgoat log: time (s, logger clock), G0..G5 (V), trigger (V)
    (with force_via = "analog", instead of the log: the gauges through the mocap's analog
    board, on the mocap clock, 2 samples per frame, channels "Nano17 G0".."Nano17 G5" and
    "Sync")
    indentation.c3d       C3D of the markers (mm) and the analog channels (ANALOG:LABELS cut
                          to a repeated "Nano17", full names in ANALOG:DESCRIPTIONS)
    indentation_a.tsv     QTM analog TSV export of the same channels
    (with force_via = "plate", instead: a force plate under the phantom, on the mocap clock)
    indentation_f_1.tsv   QTM force-plate export: force, moment, centre of pressure
                          (sim.twin.twin_plate)
    FT<serial>.cal        ATI calibration (SI-12-0.12; not with a plate: no Nano17)
    truth.h5              the truth (data_schema.truth)
    recording.rrd         the rerun recording of one press (when asked for)

Clock convention: an event at mocap time ``t_m`` (0 at the first frame) is stamped by the
logger at ``t_f = offset_s + (1 + drift_ppm * 1e-6) * t_m``; the log starts before the mocap
(with the indenter still and unloaded, so it can be tared) and ends after it. Through the
analog board or the force plate offset and drift are 0: the first sample is at the first
frame.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from data_schema.interior import write_interior
from data_schema.session import SCHEMA as SESSION_SCHEMA
from data_schema.session import VERSION as SESSION_VERSION
from data_schema.shape import write_stl
from ingest.ati_cal import write_ati_cal
from ingest.qtm_force_plate import WRENCH, corner_keys
from sim.twin.indenter import BODY_NAME
from sim.twin.lab_writers import (
    write_c3d,
    write_force_csv,
    write_force_mat,
    write_qtm_3d,
    write_qtm_6d,
    write_qtm_analog,
    write_qtm_force_plate,
    write_session_toml,
)
from sim.twin.twin import Twin
from sim.twin.twin_interior import interior_volume
from sim.twin.twin_plate import PLATE, plate_corners_mm, plate_samples
from sim.twin.twin_scene import TRIGGER_EVENT

FILES = {"trial": "indentation.tsv", "bodies": "indentation_6D.tsv", "pivot": "pivot.tsv",
         "csv": "force.csv", "mat": "force.mat", "c3d": "indentation.c3d",
         "analog": "indentation_a.tsv", "plate": "indentation_f_1.tsv",
         "session": "session.toml", "truth": "truth.h5", "interior": "interior.nii.gz",
         "shape": "mould.stl"}
GAUGES = tuple(f"G{k}" for k in range(6))
TRIGGER_COLUMN = "trigger"
# the analog route: channel names, the label a C3D export cuts them to (repeated), the board
ANALOG_GAUGES = tuple(f"Nano17 G{k}" for k in range(6))
ANALOG_LABEL = "Nano17"
ANALOG_TRIGGER = "Sync"
ANALOG_SCALE = 10.0 / 32768        # V per count of a +-10 V 16-bit board (C3D ANALOG:SCALE)
ROUTE_FILES = {"logger": ("csv", "mat"), "analog": ("c3d", "analog"), "plate": ("plate",)}
RECORDING = "recording.rrd"         # the recording's default name in the folder


def file_keys(twin: Twin) -> tuple[str, ...]:
    """The :data:`FILES` keys a session writes (the force route's own), truth last."""
    regions = twin.phantom.spec.inclusions or twin.phantom.spec.layer is not None
    return ("trial", "bodies", "pivot", *ROUTE_FILES[twin.params.force_via], "session",
            *(("interior",) if regions else ()),
            *(("shape",) if twin.phantom.spec.shape is not None else ()), "truth")


def calibration_name(twin: Twin) -> str | None:
    """The ATI calibration's file name, ``FT<serial>.cal``; None where no Nano17 measures
    the force (a force plate)."""
    return None if twin.params.force_via == "plate" else f"{twin.sensor.serial}.cal"


def write_lab_files(twin: Twin, out: dict[str, Path]) -> None:
    """Every lab file of the session (all but the truth) to the paths ``out`` names by
    :data:`FILES` key, and the calibration to ``out["cal"]`` (absent: no calibration)."""
    p, m = twin.params, twin.mocap
    stamp, mat_date = _stamp(p.seed)
    write_qtm_3d(out["trial"], _marker_names(twin), m.measured, p.rate_hz, stamp, m.events)
    write_qtm_6d(out["bodies"], BODY_NAME, m.body_origin, m.body_rotation, m.body_residual,
                 p.rate_hz, stamp, m.events)
    write_qtm_3d(out["pivot"], list(twin.indenter.names), twin.pivot.measured, p.rate_hz,
                 _stamp(p.seed, minutes_before=4)[0])
    if p.force_via == "analog":
        _write_analog(twin, out["c3d"], out["analog"], stamp)
    elif p.force_via == "plate":
        write_qtm_force_plate(out["plate"], plate_samples(twin), p.logger_hz, stamp,
                              _plate_keys(twin))
    else:
        _write_logger(twin, out["csv"], out["mat"], mat_date)
    if out.get("cal") is not None:
        write_ati_cal(out["cal"], twin.sensor.calibration)
    if out.get("interior") is not None:
        labels, affine, _ = interior_volume(twin.phantom.spec)
        write_interior(out["interior"], labels, affine)
    if out.get("shape") is not None:
        if twin.phantom.spec.shape is None:
            raise ValueError("a flat twin has no shape file to write")
        write_stl(out["shape"], twin.phantom.spec.shape.shape)
    write_session_toml(out["session"], *_session_tables(twin, calibration_name(twin)))


def _stamp(seed: int, minutes_before: int = 0) -> tuple[str, str]:
    """A fixed QTM TIME_STAMP (date with ms, then seconds since the PC started) and a MAT date."""
    day = np.datetime64("2021-03-01") + np.timedelta64(seed % 300, "D")
    secs = 9 * 3600 + (seed * 7919) % 28800 - 60 * minutes_before
    hh, mm, ss = secs // 3600, secs // 60 % 60, secs % 60
    ms = (seed * 37) % 1000
    date = str(day)
    ticks = 3600.0 + (seed * 104729) % 500000 + secs + ms / 1000
    return f"{date}, {hh:02d}:{mm:02d}:{ss:02d}.{ms:03d}\t{ticks:.8f}", f"{date} {hh:02d}:{mm:02d}"


def _marker_names(twin: Twin) -> list[str]:
    return [*twin.phantom.spec.markers.names, *twin.indenter.names]


def _write_logger(twin: Twin, csv: Path, mat: Path, mat_date: str) -> None:
    """The Speedgoat log, as CSV and MAT v7."""
    columns = {"time": twin.log.time_s,
               **{g: twin.log.volts[:, i] for i, g in enumerate(GAUGES)}}
    formats = {"time": "%.3f", **dict.fromkeys(GAUGES, "%.6f"), TRIGGER_COLUMN: "%.4f"}
    if twin.log.trigger is not None:
        columns[TRIGGER_COLUMN] = twin.log.trigger
    write_force_csv(csv, columns, formats)
    write_force_mat(mat, columns, "MATLAB 5.0 MAT-file, Platform: GLNXA64, Created on: "
                                  f"{mat_date}  Speedgoat log export")


def _write_analog(twin: Twin, c3d: Path, tsv: Path, stamp: str) -> None:
    """The gauges through the mocap's analog board: the C3D export (markers and analog
    channels, labels cut to ``ANALOG_LABEL``) and the QTM analog TSV export."""
    p, log = twin.params, twin.log
    channels = {g: log.volts[:, i] for i, g in enumerate(ANALOG_GAUGES)}
    labels = [ANALOG_LABEL] * len(channels)
    if log.trigger is not None:
        channels[ANALOG_TRIGGER] = log.trigger
        labels.append(ANALOG_TRIGGER)
    write_c3d(c3d, _marker_names(twin), twin.mocap.measured, p.rate_hz, channels, p.logger_hz,
              labels, ["V"] * len(channels), ANALOG_SCALE)
    write_qtm_analog(tsv, channels, p.logger_hz, stamp)


def _plate_keys(twin: Twin) -> list[tuple[str, str]]:
    """The export's ``FORCE_PLATE_*`` header keys: the plate's type, model, name, corners
    (lab, mm) and size."""
    corners = plate_corners_mm(twin).ravel()
    return [("FORCE_PLATE_TYPE", PLATE.type), ("FORCE_PLATE_MODEL", PLATE.model),
            ("FORCE_PLATE_NAME", PLATE.name),
            *((k, f"{v:.3f}") for k, v in zip(corner_keys(), corners, strict=True)),
            ("FORCE_PLATE_LENGTH", f"{PLATE.length_mm:.3f}"),
            ("FORCE_PLATE_WIDTH", f"{PLATE.width_mm:.3f}")]


def _session_tables(twin: Twin, cal_name: str | None) -> tuple[dict, dict]:
    p = twin.params
    mocap: dict[str, object] = {
        "file": FILES["trial"], "bodies_file": FILES["bodies"],
        "phantom_markers": list(twin.phantom.spec.markers.names),
        "indenter_markers": list(twin.indenter.names),
        "indenter_body": BODY_NAME}
    source = "plate" if p.force_via == "plate" else \
        {"csv": "csv", "mat": "mat", "tsv": "analog", "c3d": "c3d"}[p.force_source]
    force: dict[str, object] = {"file": FILES[source]}
    if p.force_via == "plate":                  # the export states N and N m
        force.update(kind="wrench", channels=list(WRENCH), rate_hz=p.logger_hz)
        other = None
    elif p.force_via == "analog":
        force.update(kind="gauge", channels=list(ANALOG_GAUGES), rate_hz=p.logger_hz,
                     calibration=cal_name)
        if source == "c3d":                     # one export holds markers and force
            mocap["file"] = FILES["c3d"]
        other = FILES["analog" if source == "c3d" else "c3d"]
    else:
        force.update(time_column="time", time_unit="s", kind="gauge", channels=list(GAUGES),
                     units="V", calibration=cal_name)
        other = FILES["mat" if source == "csv" else "csv"]
        if p.trigger:
            mocap["trigger_event"] = TRIGGER_EVENT
            force["trigger_column"] = TRIGGER_COLUMN
    top = {"schema": SESSION_SCHEMA, "schema_version": SESSION_VERSION,
           "name": f"phantom-twin-seed{p.seed}"}
    synth = {"seed": p.seed, "truth": FILES["truth"],
             **({"other_force_file": other} if other else {})}
    return top, {"mocap": mocap, "force": force, "pivot": {"file": FILES["pivot"]},
                 "phantom": phantom_table(twin), "synth": synth}


def phantom_table(twin: Twin) -> dict[str, object]:
    """session.toml's ``[phantom]``: the footprint; a non-square grid's rows; for a scattered
    layout the in-plane axis (P00 -> P01, laid along +x) and P00's true place on the
    footprint (``[0, L] x [0, W]``, mm). A grid needs neither: its rows run along +x and it is
    centred on the block."""
    spec, ph = twin.phantom.spec, twin.phantom
    size = [round(float(s) * 1e3, 6) for s in spec.size[:2]]
    table: dict[str, object] = {"size_mm": size}
    layout = spec.markers
    if layout.scattered:
        names = layout.names
        rest = ph.rest[ph.top(*ph.marker_ij[0])]
        table.update(x_axis=[names[0], names[1]], anchor=names[0],
                     anchor_mm=[round(float(rest[0]) * 1e3 + size[0] / 2, 6),
                                round(float(rest[1]) * 1e3 + size[1] / 2, 6)])
    elif layout.rows != layout.cols:
        table["rows"] = layout.rows
    if spec.inclusions or spec.layer is not None:
        table.update(interior=FILES["interior"], labels=interior_volume(spec)[2])
    if spec.shape is not None:
        table.update(shape=FILES["shape"],
                     marker_diameter_mm=round(2 * spec.marker_radius * 1e3, 6))
    return table

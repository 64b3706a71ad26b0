"""The phantom twin's session folder: what the lab would hand over, plus the truth.

``synthesize_session`` plays a session (:func:`sim.twin.simulate`) and writes it in the lab's
formats (:mod:`sim.lab_writers`, :mod:`ingest.ati_cal`) with ``truth.h5``
(:mod:`sim.twin_truth`) and, when asked, a rerun recording (:mod:`sim.twin_view`). The same
seed gives the same bytes of every data file.

Session folder::

    session.toml          which file is which (data_schema.session)
    indentation.tsv       QTM TSV 3D, 500 Hz, 25 phantom + 4 indenter markers, EVENT Trigger lines
    indentation_6D.tsv    QTM TSV 6D of the body "Indenter"
    pivot.tsv             QTM TSV 3D of the 4 indenter markers, tip held in a divot
    force.csv, force.mat  the Speedgoat log: time (s, logger clock), G0..G5 (V), trigger (V)
    (with force_via = "analog", instead of the log: the gauges through the mocap's analog
    board, on the mocap clock, 2 samples per frame, channels "Nano17 G0".."Nano17 G5" and
    "Sync")
    indentation.c3d       C3D of the markers (mm) and the analog channels (ANALOG:LABELS cut
                          to a repeated "Nano17", full names in ANALOG:DESCRIPTIONS)
    indentation_a.tsv     QTM analog TSV export of the same channels
    FT<serial>.cal        ATI calibration (SI-12-0.12)
    truth.h5              the truth (data_schema.truth)
    recording.rrd         the rerun recording of one press (when asked for)

Writing over an earlier session removes its files that the new one does not write (another
sensor's ``FT<serial>.cal``, a recording) and leaves every other file alone.

Clock convention: an event at mocap time ``t_m`` (0 at the first frame) is stamped by the
logger at ``t_f = offset_s + (1 + drift_ppm * 1e-6) * t_m``; the log starts before the mocap
(with the indenter still and unloaded, so it can be tared) and ends after it. Through the
analog board offset and drift are 0: the first sample is at the first frame.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from core.atomic import atomic_outputs
from core.errors import BadInput
from data_schema.session import SCHEMA as SESSION_SCHEMA
from data_schema.session import VERSION as SESSION_VERSION
from ingest.ati_cal import write_ati_cal
from sim.indenter import BODY_NAME
from sim.lab_writers import (
    write_c3d,
    write_force_csv,
    write_force_mat,
    write_qtm_3d,
    write_qtm_6d,
    write_qtm_analog,
    write_session_toml,
)
from sim.twin import Twin, simulate
from sim.twin_scene import PHANTOM_MARKERS, TRIGGER_EVENT, TwinParams
from sim.twin_truth import write_truth
from sim.twin_view import write_twin_recording

FILES = {"trial": "indentation.tsv", "bodies": "indentation_6D.tsv", "pivot": "pivot.tsv",
         "csv": "force.csv", "mat": "force.mat", "c3d": "indentation.c3d",
         "analog": "indentation_a.tsv", "session": "session.toml", "truth": "truth.h5"}
GAUGES = tuple(f"G{k}" for k in range(6))
TRIGGER_COLUMN = "trigger"
# the analog route: channel names, the label a C3D export cuts them to (repeated), the board
ANALOG_GAUGES = tuple(f"Nano17 G{k}" for k in range(6))
ANALOG_LABEL = "Nano17"
ANALOG_TRIGGER = "Sync"
ANALOG_SCALE = 10.0 / 32768        # V per count of a +-10 V 16-bit board (C3D ANALOG:SCALE)
RECORDING = "recording.rrd"         # the recording's default name in the folder


def synthesize_session(out_dir: str | Path, seed: int = 0, locations: int = 5,
                       repeats: int = 4, rrd: str | Path | None = None, view_press: int = 0,
                       **params: object) -> Path:
    """Simulate a session and write its folder (see the module docstring); returns the folder.

    ``params`` are further :class:`TwinParams` fields; ``rrd`` also writes a rerun recording of
    press ``view_press``.
    """
    p = TwinParams(seed=seed, locations=locations, repeats=repeats, **params)
    folder = _output_folder(out_dir)
    if rrd is not None and not 0 <= view_press < locations * repeats:
        raise BadInput("--view-press",
                       f"press {view_press} does not exist (0..{locations * repeats - 1})")
    twin = simulate(p)
    write_twin(twin, folder, rrd, view_press)
    return folder


def _output_folder(out_dir: str | Path) -> Path:
    """The session folder: new, empty, or an earlier twin session (then overwritten)."""
    folder = Path(out_dir)
    if folder.exists() and not folder.is_dir():
        raise BadInput(folder, "exists and is not a folder")
    if folder.is_dir() and any(folder.iterdir()) and not (folder / FILES["truth"]).is_file():
        raise BadInput(folder, "folder is not empty and holds no earlier synthetic session; "
                               "choose a new or empty folder")
    return folder


def _stamp(seed: int, minutes_before: int = 0) -> tuple[str, str]:
    """A fixed QTM TIME_STAMP (date with ms, then seconds since the PC started) and a MAT date."""
    day = np.datetime64("2021-03-01") + np.timedelta64(seed % 300, "D")
    secs = 9 * 3600 + (seed * 7919) % 28800 - 60 * minutes_before
    hh, mm, ss = secs // 3600, secs // 60 % 60, secs % 60
    ms = (seed * 37) % 1000
    date = str(day)
    ticks = 3600.0 + (seed * 104729) % 500000 + secs + ms / 1000
    return f"{date}, {hh:02d}:{mm:02d}:{ss:02d}.{ms:03d}\t{ticks:.8f}", f"{date} {hh:02d}:{mm:02d}"


def write_twin(twin: Twin, folder: str | Path, rrd: str | Path | None = None,
               view_press: int = 0) -> None:
    """Write every file of the session folder (atomically: all or nothing).

    Over an earlier session (the folder holds a ``truth.h5``), the files that session wrote
    and this one does not (another sensor's ``FT<serial>.cal``, a ``recording.rrd`` this run
    skips, the other force route's files) are removed once the new files are in place; no
    other file is touched.
    """
    p, folder = twin.params, Path(folder)
    earlier = (folder / FILES["truth"]).is_file()
    cal_name = f"{twin.sensor.serial}.cal"
    force_keys = ("c3d", "analog") if p.force_via == "analog" else ("csv", "mat")
    keys = ("trial", "bodies", "pivot", *force_keys, "session", "truth")
    finals = [folder / FILES[k] for k in keys] + [folder / cal_name]
    if rrd is not None and Path(rrd).resolve() in {f.resolve() for f in finals}:
        raise BadInput(rrd, "--rrd names one of the session files synth writes")
    stamp, mat_date = _stamp(p.seed)
    m = twin.mocap
    with atomic_outputs(*finals, rrd) as tmps:
        out = dict(zip([*keys, "cal", "rrd"], tmps, strict=True))
        write_qtm_3d(out["trial"], _marker_names(twin), m.measured, p.rate_hz, stamp, m.events)
        write_qtm_6d(out["bodies"], BODY_NAME, m.body_origin, m.body_rotation, m.body_residual,
                     p.rate_hz, stamp, m.events)
        write_qtm_3d(out["pivot"], list(twin.indenter.names), twin.pivot.measured, p.rate_hz,
                     _stamp(p.seed, minutes_before=4)[0])
        if p.force_via == "analog":
            _write_analog(twin, out["c3d"], out["analog"], stamp)
        else:
            _write_logger(twin, out["csv"], out["mat"], mat_date)
        write_ati_cal(out["cal"], twin.sensor.calibration)
        write_session_toml(out["session"], *_session_tables(twin, cal_name))
        write_truth(out["truth"], twin)
        if out["rrd"] is not None:
            write_twin_recording(twin, out["rrd"], view_press)
    if earlier:
        _remove_stale(folder, [*finals, rrd])


def _marker_names(twin: Twin) -> list[str]:
    return [*PHANTOM_MARKERS, *twin.indenter.names]


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


def _remove_stale(folder: Path, written: list[Path | str | None]) -> None:
    """Remove the files of an earlier session in ``folder`` that this one did not write."""
    keep = {Path(f).resolve() for f in written if f is not None}
    for f in folder.iterdir():
        if f.is_file() and _twin_file(f.name) and f.resolve() not in keep:
            f.unlink()


def _twin_file(name: str) -> bool:
    """Whether a session folder's file named ``name`` is one the twin writes."""
    return (name in FILES.values() or name == RECORDING
            or re.fullmatch(r"FT\d{5}\.cal", name) is not None)


def _session_tables(twin: Twin, cal_name: str) -> tuple[dict, dict]:
    p = twin.params
    mocap: dict[str, object] = {
        "file": FILES["trial"], "bodies_file": FILES["bodies"],
        "phantom_markers": list(PHANTOM_MARKERS), "indenter_markers": list(twin.indenter.names),
        "indenter_body": BODY_NAME}
    source = {"csv": "csv", "mat": "mat", "tsv": "analog", "c3d": "c3d"}[p.force_source]
    force: dict[str, object] = {"file": FILES[source]}
    if p.force_via == "analog":
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
    synth = {"seed": p.seed, "truth": FILES["truth"], "other_force_file": other}
    return top, {"mocap": mocap, "force": force, "pivot": {"file": FILES["pivot"]},
                 "synth": synth}

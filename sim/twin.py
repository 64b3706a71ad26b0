"""The phantom twin: a whole lab session simulated, written in the lab's formats, plus the truth.

``synthesize_session`` plays a session: a volumetric silicone block (:mod:`sim.phantom`) on the
table, 5 x 5 markers on its top, an indenter cluster held by a hand (:mod:`sim.indenter`)
pressing each location several times, a pivot calibration, Qualisys noise and occlusions
(:mod:`sim.mocap_errors`), a Nano17 logged by a Speedgoat on its own clock (:mod:`sim.nano17`).
It writes what the lab would hand over (:mod:`sim.lab_writers`) and ``truth.h5``
(:mod:`data_schema.truth`). The same seed gives the same bytes of every data file.

Session folder::

    session.toml          which file is which (data_schema.session)
    indentation.tsv       QTM TSV 3D, 500 Hz, 25 phantom + 4 indenter markers, EVENT Trigger lines
    indentation_6D.tsv    QTM TSV 6D of the body "Indenter"
    pivot.tsv             QTM TSV 3D of the 4 indenter markers, tip held in a divot
    force.csv, force.mat  the Speedgoat log: time (s, logger clock), G0..G5 (V), trigger (V)
    FT<serial>.cal        ATI calibration (SI-12-0.12)
    truth.h5              the truth (data_schema.truth)
    recording.rrd         the rerun recording of one press (when asked for)

Writing over an earlier session removes its files that the new one does not write (another
sensor's ``FT<serial>.cal``, a recording) and leaves every other file alone.

Clock convention: an event at mocap time ``t_m`` (0 at the first frame) is stamped by the
logger at ``t_f = offset_s + (1 + drift_ppm * 1e-6) * t_m``; the log starts before the mocap
(with the indenter still and unloaded, so it can be tared) and ends after it.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from functools import partial
from pathlib import Path

import h5py
import numpy as np

from calib.rigid import fit_rigid
from core.atomic import atomic_outputs
from core.errors import BadInput
from core.progress import progress
from core.provenance import make_provenance
from data_schema.hdf5 import validate_h5
from data_schema.session import SCHEMA as SESSION_SCHEMA
from data_schema.session import VERSION as SESSION_VERSION
from data_schema.truth import CLOCK_DOC, TRUTH
from ingest.ati_cal import write_ati_cal
from sim.indenter import (
    BODY_NAME,
    GRAVITY,
    Hand,
    HandStyle,
    IndenterGeometry,
    make_indenter,
    pivot_motion,
    plan_hand,
)
from sim.lab_writers import (
    write_force_csv,
    write_force_mat,
    write_qtm_3d,
    write_qtm_6d,
    write_session_toml,
)
from sim.mocap_errors import MocapErrors, gap_mask, gap_rates, residual_noise
from sim.nano17 import Nano17, make_nano17
from sim.phantom import LoadPath, Phantom, PhantomSpec

FILES = {"trial": "indentation.tsv", "bodies": "indentation_6D.tsv", "pivot": "pivot.tsv",
         "csv": "force.csv", "mat": "force.mat", "session": "session.toml",
         "truth": "truth.h5"}
PHANTOM_MARKERS = tuple(f"P{k:02d}" for k in range(25))
GAUGES = tuple(f"G{k}" for k in range(6))
TRIGGER_EVENT, TRIGGER_COLUMN = "Trigger", "trigger"
STEP_N = 0.5                        # static states every 0.5 N
RECORDING = "recording.rrd"         # the recording's default name in the folder


@dataclass(frozen=True)
class TwinParams:
    """Everything that shapes a synthetic session."""

    seed: int = 0
    locations: int = 5
    repeats: int = 4
    press_seconds: float | None = None   # mean duration of one press cycle (None: ~6 s)
    pivot_seconds: float = 20.0
    rate_hz: float = 500.0
    logger_hz: float = 1000.0
    trigger: bool = True
    offset_s: float | None = None        # None: drawn, |offset| in [0.3, 3] s, either sign
    drift_ppm: float | None = None       # None: drawn, |drift| in [10, 60] ppm, either sign
    force_file: str = "csv"              # the log session.toml names: csv or mat
    errors: MocapErrors = field(default_factory=MocapErrors)
    phantom: PhantomSpec = field(default_factory=PhantomSpec)


@dataclass
class Mocap:
    """The trial on the mocap clock: truth and what the cameras delivered."""

    time_s: np.ndarray          # (T,)
    points: np.ndarray          # (T, 26, 3) truth: phantom markers + tip
    cluster: np.ndarray         # (T, 4, 3) truth
    origin: np.ndarray          # (T, 3) body origin
    rotation: np.ndarray        # (T, 3, 3) body -> lab
    press: np.ndarray           # (T,) press in contact or -1
    force: np.ndarray           # (T,) contact force magnitude
    force_lab: np.ndarray       # (T, 3) on the phantom
    force_sensor: np.ndarray    # (T, 3) on the tip, sensor frame
    torque_sensor: np.ndarray   # (T, 3)
    visible: np.ndarray         # (T, 29)
    measured: np.ndarray        # (T, 29, 3) noisy, NaN in gaps
    body_origin: np.ndarray     # (T, 3) QTM's 6D fit of the measured cluster, NaN when lost
    body_rotation: np.ndarray   # (T, 3, 3)
    body_residual: np.ndarray   # (T,)
    events: list[tuple[str, int, float]]


@dataclass
class ForceLog:
    """The Speedgoat log on its own clock, with the truth behind it."""

    time_s: np.ndarray          # (L,) logger clock
    mocap_time_s: np.ndarray    # (L,)
    force: np.ndarray           # (L, 3) contact force on the tip, sensor frame
    torque: np.ndarray          # (L, 3)
    tool_force: np.ndarray      # (L, 3)
    volts: np.ndarray           # (L, 6)
    trigger: np.ndarray | None  # (L,) volts
    offset_s: float
    drift_ppm: float
    pulses: np.ndarray          # (K,) rising edges, mocap clock


@dataclass
class Pivot:
    """The pivot-calibration recording (its own mocap clock)."""

    time_s: np.ndarray
    point: np.ndarray           # (3,) the divot
    rotation: np.ndarray        # (Q, 3, 3)
    cluster: np.ndarray         # (Q, 4, 3) truth
    measured: np.ndarray        # (Q, 4, 3) noisy, NaN in gaps


@dataclass
class States:
    """True static states every 0.5 N of each press's loading phase."""

    points: np.ndarray          # (S, 26, 3)
    force: np.ndarray           # (S,)
    force_vector: np.ndarray    # (S, 3)
    step: np.ndarray
    press: np.ndarray
    location: np.ndarray
    time_s: np.ndarray


@dataclass
class Twin:
    """A simulated session in memory, ready to be written."""

    params: TwinParams
    phantom: Phantom
    to_lab: np.ndarray          # (4, 4)
    nodes: np.ndarray           # (C, 2) top lattice nodes of the locations
    contacts: np.ndarray        # (C, 3) lab
    indenter: IndenterGeometry
    sensor: Nano17
    hand: Hand
    paths: list[LoadPath]
    mocap: Mocap
    log: ForceLog
    pivot: Pivot
    states: States

    def lab(self, p: np.ndarray) -> np.ndarray:
        """Phantom-frame points (..., 3) in the lab."""
        return _apply(self.to_lab, p)


Lab = Callable[[np.ndarray], np.ndarray]


def _apply(to_lab: np.ndarray, p: np.ndarray) -> np.ndarray:
    return np.asarray(p) @ to_lab[:3, :3].T + to_lab[:3, 3]


# ------------------------------------------------------------------------------ entry point


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


def simulate(p: TwinParams) -> Twin:
    """Play the whole session in memory."""
    _check_params(p)
    rng = [np.random.default_rng(s) for s in np.random.SeedSequence(p.seed).spawn(8)]
    g_place, g_hand, g_cam, g_force, g_clock, g_pivot, g_build, g_gap = rng
    phantom = Phantom(p.phantom)
    to_lab = _placement(g_place)
    lab = partial(_apply, to_lab)
    nodes = _choose_locations(g_place, phantom, p.locations)
    contacts = lab(np.array([phantom.contact_point(tuple(ij)) for ij in nodes]))
    targets = [(loc, rep, contacts[loc]) for rep in range(p.repeats)
               for loc in range(p.locations)]
    style = HandStyle()
    if p.press_seconds is not None:
        style = replace(style, scale=p.press_seconds / style.mean_press_s)
    hand = plan_hand(g_hand, targets, style)
    paths = _solve_presses(phantom, hand, nodes, to_lab)
    indenter = make_indenter(g_build)
    sensor = make_nano17(g_build, f"FT{21000 + p.seed % 79000:05d}")
    frames = int(np.ceil(hand.end * p.rate_hz))
    time_s = np.arange(frames) / p.rate_hz
    mocap = _mocap(p, phantom, lab, hand, paths, indenter, time_s, g_cam, g_gap)
    log = _force_log(p, hand, indenter, sensor, time_s[-1], g_force, g_clock)
    mocap.events = [(TRIGGER_EVENT, int(np.floor(t * p.rate_hz + 1e-9)) + 1, float(t))
                    for t in log.pulses] if p.trigger else []
    pivot = _pivot(p, indenter, lab, g_pivot, g_gap)
    states = _states(hand, paths, lab, mocap)
    return Twin(params=p, phantom=phantom, to_lab=to_lab, nodes=nodes, contacts=contacts,
                indenter=indenter, sensor=sensor, hand=hand, paths=paths, mocap=mocap, log=log,
                pivot=pivot, states=states)


def _check_params(p: TwinParams) -> None:
    checks = [
        ("--locations", p.locations >= 1, "must be at least 1"),
        ("--repeats", p.repeats >= 1, "must be at least 1"),
        ("--force-file", p.force_file in ("csv", "mat"), "must be csv or mat"),
        ("--press-seconds", p.press_seconds is None or 2.0 <= p.press_seconds <= 60.0,
         "must be between 2 and 60 s"),
        ("--pivot-seconds", 2.0 <= p.pivot_seconds <= 600.0, "must be between 2 and 600 s"),
        ("--drift", p.drift_ppm is None or abs(p.drift_ppm) <= 1000.0,
         "beyond 1000 ppm is not a clock"),
        ("--offset", p.offset_s is None or abs(p.offset_s) <= 3600.0,
         "beyond an hour is not plausible"),
    ]
    for option, ok, what in checks:
        if not ok:
            raise BadInput(option, what)


def _output_folder(out_dir: str | Path) -> Path:
    """The session folder: new, empty, or an earlier twin session (then overwritten)."""
    folder = Path(out_dir)
    if folder.exists() and not folder.is_dir():
        raise BadInput(folder, "exists and is not a folder")
    if folder.is_dir() and any(folder.iterdir()) and not (folder / FILES["truth"]).is_file():
        raise BadInput(folder, "folder is not empty and holds no earlier synthetic session; "
                               "choose a new or empty folder")
    return folder


# ------------------------------------------------------------------------------ the scene


def _placement(rng: np.random.Generator) -> np.ndarray:
    """Phantom frame -> lab: turned a little about the vertical, somewhere on the table."""
    yaw = np.radians(rng.uniform(-8.0, 8.0))
    c, s = np.cos(yaw), np.sin(yaw)
    out = np.eye(4)
    out[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    out[:3, 3] = [rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), 0.0]
    return out


def _choose_locations(rng: np.random.Generator, phantom: Phantom, n: int,
                      min_gap: float = 0.015) -> np.ndarray:
    """``n`` candidate nodes at least ``min_gap`` apart, in random order."""
    cand = phantom.candidate_locations()
    chosen: list[np.ndarray] = []
    for i in rng.permutation(len(cand)):
        xy = phantom.contact_point(tuple(cand[i]))[:2]
        if all(np.linalg.norm(xy - phantom.contact_point(tuple(c))[:2]) >= min_gap
               for c in chosen):
            chosen.append(cand[i])
        if len(chosen) == n:
            return np.array(chosen)
    raise BadInput("--locations", f"only {len(chosen)} locations fit on the phantom "
                         f"({min_gap * 1e3:.0f} mm apart); asked for {n}")


def _levels(fmax: float, top: float) -> np.ndarray:
    """Force levels to solve: every 0.5 N up to fmax, 0.25 N, fmax and a margin above it."""
    steps = STEP_N * np.arange(1, int(np.floor(fmax / STEP_N + 1e-9)) + 1)
    extra = [f for f in (0.25, fmax, top) if np.all(np.abs(steps - f) > 0.01)]
    return np.unique(np.concatenate([steps, extra]))


def _solve_presses(phantom: Phantom, hand: Hand, nodes: np.ndarray,
                   to_lab: np.ndarray) -> list[LoadPath]:
    paths = []
    with progress(range(len(hand.presses)), label="synth: phantom") as bar:
        for k in bar:
            press = hand.presses[k]
            direction = to_lab[:3, :3].T @ press.direction
            levels = _levels(press.fmax, hand.max_force(k) + 0.01)
            paths.append(phantom.load_path(tuple(nodes[press.location]), direction, levels))
    return paths


# ------------------------------------------------------------------------------ mocap


def _mocap(p: TwinParams, phantom: Phantom, lab: Lab, hand: Hand, paths: list[LoadPath],
           indenter: IndenterGeometry, time_s: np.ndarray, g_cam: np.random.Generator,
           g_gap: np.random.Generator) -> Mocap:
    st = hand.state(time_s)
    rest_markers = lab(phantom.observe(np.zeros(phantom.n_dof))[1])
    tip = st.tip_air.copy()
    markers = np.repeat(rest_markers[None], len(time_s), axis=0)
    force_lab = np.zeros((len(time_s), 3))
    for k, path in enumerate(paths):
        idx = np.flatnonzero(st.press == k)
        tip[idx] = lab(path.interpolate(st.force[idx], "tip"))
        markers[idx] = lab(path.interpolate(st.force[idx], "markers"))
        force_lab[idx] = st.force[idx, None] * hand.presses[k].direction
    cluster = tip[:, None] + np.einsum("tij,mj->tmi", st.rotation,
                                       indenter.markers - indenter.tip)
    origin = tip - st.rotation @ indenter.tip
    force_sensor, torque = _contact_wrench(indenter, st.rotation, force_lab)

    truth = np.concatenate([markers, cluster], axis=1)
    top = lab(np.array([0.0, 0.0, p.phantom.size[2]]))[2]
    rates = gap_rates(tip, tip[:, 2] - top, rest_markers, cluster.shape[1], p.errors)
    visible = gap_mask(g_gap, rates, p.rate_hz, p.errors)
    measured = truth + residual_noise(g_cam, truth.shape[:2], p.errors)
    measured[~visible] = np.nan
    fit = fit_rigid(indenter.markers, measured[:, 25:], max_rms=1.0, drop_outlier=False)
    return Mocap(
        time_s=time_s, points=np.concatenate([markers, tip[:, None]], axis=1), cluster=cluster,
        origin=origin, rotation=st.rotation, press=st.press, force=st.force,
        force_lab=force_lab, force_sensor=force_sensor, torque_sensor=torque,
        visible=visible, measured=measured, body_origin=fit.translation,
        body_rotation=fit.rotation, body_residual=fit.rms, events=[])


# ------------------------------------------------------------------------------ force log


def _force_log(p: TwinParams, hand: Hand, indenter: IndenterGeometry, sensor: Nano17,
               last_frame_s: float, g_force: np.random.Generator,
               g_clock: np.random.Generator) -> ForceLog:
    """Logger samples on its own clock, covering the mocap with an unloaded lead.

    The clock's offset and drift are always drawn, then replaced by ``p.offset_s`` and
    ``p.drift_ppm`` where given: setting them changes no other random choice.
    """
    sign = g_clock.choice([-1.0, 1.0], 2)
    offset = sign[0] * g_clock.uniform(0.3, 3.0)
    drift = sign[1] * g_clock.uniform(10.0, 60.0)
    offset = offset if p.offset_s is None else p.offset_s
    drift = drift if p.drift_ppm is None else p.drift_ppm
    lead, tail = g_clock.uniform(1.5, 3.0), g_clock.uniform(0.5, 2.0)
    scale = 1.0 + drift * 1e-6
    first = int(np.ceil((offset - scale * lead) * p.logger_hz))
    last = int(np.floor((offset + scale * (last_frame_s + tail)) * p.logger_hz))
    t_f = np.arange(first, last + 1) / p.logger_hz
    t_m = (t_f - offset) / scale

    st = hand.state(t_m)
    directions = np.vstack([np.zeros(3), *(q.direction for q in hand.presses)])
    force, torque = _contact_wrench(indenter, st.rotation,
                                    st.force[:, None] * directions[st.press + 1])
    tool = np.einsum("tji,j->ti", st.rotation, indenter.tool_mass * GRAVITY)
    tool_torque = np.cross(indenter.tool_centre - indenter.sensor, tool)
    volts = sensor.volts(g_force, force + tool, torque + tool_torque, t_f)

    pulses = np.array([])
    trigger = None
    if p.trigger:
        pulses = _pulse_times(g_clock, last_frame_s)
        k = np.searchsorted(pulses, t_m, side="right") - 1
        high = (k >= 0) & (t_m < pulses[np.maximum(k, 0)] + 0.010)
        trigger = np.where(high, 5.0, 0.0) + g_force.normal(0.0, 0.002, len(t_m))
    return ForceLog(time_s=t_f, mocap_time_s=t_m, force=force, torque=torque, tool_force=tool,
                    volts=volts, trigger=trigger, offset_s=float(offset),
                    drift_ppm=float(drift), pulses=pulses)


def _contact_wrench(indenter: IndenterGeometry, rotation: np.ndarray, force_lab: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Force and torque (T, 3) the sensor feels from the contact, in its own frame.

    ``force_lab`` (T, 3) is the force the indenter exerts on the phantom; the phantom pushes
    back on the tip with its opposite, applied at the tip, taken about the sensor's origin.
    ``rotation`` (T, 3, 3) is body (= sensor axes) to lab.
    """
    force = -np.einsum("tji,tj->ti", rotation, force_lab)
    return force, np.cross(indenter.tip - indenter.sensor, force)


def _pulse_times(rng: np.random.Generator, end_s: float) -> np.ndarray:
    """TTL sync pulses at irregular intervals (so that no shift of the train fits but one)."""
    times, t = [], rng.uniform(0.3, 0.8)
    while t < end_s - 0.3:
        times.append(t)
        t += rng.uniform(0.7, 2.3)
    return np.array(times)


# ------------------------------------------------------------------------------ pivot, states


def _pivot(p: TwinParams, indenter: IndenterGeometry, lab: Lab, g_pivot: np.random.Generator,
           g_gap: np.random.Generator) -> Pivot:
    """The tip in a divot on the table beside the phantom; the cluster swung about it."""
    time_s = np.arange(int(round(p.pivot_seconds * p.rate_hz))) / p.rate_hz
    point = lab(np.array([0.08, -0.02, 0.003]))
    rotation, cluster = pivot_motion(g_pivot, indenter, point, time_s)
    rates = np.full(cluster.shape[:2], p.errors.indenter_rate)
    measured = cluster + residual_noise(g_pivot, cluster.shape[:2], p.errors)
    measured[~gap_mask(g_gap, rates, p.rate_hz, p.errors)] = np.nan
    return Pivot(time_s=time_s, point=point, rotation=rotation, cluster=cluster,
                 measured=measured)


def _states(hand: Hand, paths: list[LoadPath], lab: Lab, mocap: Mocap) -> States:
    rows: dict[str, list] = {k: [] for k in ("points", "force", "vector", "step", "press",
                                             "location", "time")}
    for k, (press, path) in enumerate(zip(hand.presses, paths, strict=True)):
        frames = np.flatnonzero(mocap.press == k)
        loading = frames[mocap.time_s[frames] <= press.times[4] + 1e-9]
        f, t = mocap.force[loading], mocap.time_s[loading]
        for step in range(int(np.floor(press.fmax / STEP_N + 1e-9)) + 1):
            level = step * STEP_N
            i = int(np.flatnonzero(np.isclose(path.forces, level, atol=1e-9))[0])
            rows["points"].append(np.concatenate([lab(path.markers[i]), lab(path.tip[i])[None]]))
            rows["force"].append(level)
            rows["vector"].append(level * press.direction)
            rows["step"].append(step)
            rows["press"].append(k)
            rows["location"].append(press.location)
            rows["time"].append(press.times[3] if step == 0 else _crossing(t, f, level))
    return States(points=np.array(rows["points"]), force=np.array(rows["force"]),
                  force_vector=np.array(rows["vector"]), step=np.array(rows["step"]),
                  press=np.array(rows["press"]), location=np.array(rows["location"]),
                  time_s=np.array(rows["time"], dtype=np.float64))


def _crossing(t: np.ndarray, f: np.ndarray, level: float) -> float:
    """First time the sampled force reaches ``level`` (linear between frames)."""
    hit = np.flatnonzero(f >= level)
    if hit.size == 0:
        return float(t[-1]) if t.size else float("nan")
    i = int(hit[0])
    if i == 0:
        return float(t[0])
    return float(t[i - 1] + (level - f[i - 1]) / (f[i] - f[i - 1]) * (t[i] - t[i - 1]))


# ------------------------------------------------------------------------------ writing


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
    skips) are removed once the new files are in place; no other file is touched.
    """
    p, folder = twin.params, Path(folder)
    earlier = (folder / FILES["truth"]).is_file()
    cal_name = f"{twin.sensor.serial}.cal"
    names = [*PHANTOM_MARKERS, *twin.indenter.names]
    finals = [folder / FILES[k] for k in ("trial", "bodies", "pivot", "csv", "mat", "session",
                                          "truth")] + [folder / cal_name]
    if rrd is not None and Path(rrd).resolve() in {f.resolve() for f in finals}:
        raise BadInput(rrd, "--rrd names one of the session files synth writes")
    stamp, mat_date = _stamp(p.seed)
    columns = {"time": twin.log.time_s, **{g: twin.log.volts[:, i] for i, g in enumerate(GAUGES)}}
    formats = {"time": "%.3f", **dict.fromkeys(GAUGES, "%.6f"), TRIGGER_COLUMN: "%.4f"}
    if twin.log.trigger is not None:
        columns[TRIGGER_COLUMN] = twin.log.trigger
    m = twin.mocap
    with atomic_outputs(*finals, rrd) as tmps:
        trial, bodies, pivot, csv, mat, session, truth, cal, tmp_rrd = tmps
        write_qtm_3d(trial, names, m.measured, p.rate_hz, stamp, m.events)
        write_qtm_6d(bodies, BODY_NAME, m.body_origin, m.body_rotation, m.body_residual,
                     p.rate_hz, stamp, m.events)
        write_qtm_3d(pivot, list(twin.indenter.names), twin.pivot.measured, p.rate_hz,
                     _stamp(p.seed, minutes_before=4)[0])
        write_force_csv(csv, columns, formats)
        write_force_mat(mat, columns, "MATLAB 5.0 MAT-file, Platform: GLNXA64, Created on: "
                                      f"{mat_date}  Speedgoat log export")
        write_ati_cal(cal, twin.sensor.calibration)
        write_session_toml(session, *_session_tables(twin, cal_name))
        write_truth(truth, twin)
        if tmp_rrd is not None:
            from sim.twin_view import write_twin_recording

            write_twin_recording(twin, tmp_rrd, view_press)
    if earlier:
        _remove_stale(folder, [*finals, rrd])


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
    force: dict[str, object] = {
        "file": FILES[p.force_file], "time_column": "time", "time_unit": "s", "kind": "gauge",
        "channels": list(GAUGES), "units": "V", "calibration": cal_name}
    if p.trigger:
        mocap["trigger_event"] = TRIGGER_EVENT
        force["trigger_column"] = TRIGGER_COLUMN
    top = {"schema": SESSION_SCHEMA, "schema_version": SESSION_VERSION,
           "name": f"phantom-twin-seed{p.seed}"}
    synth = {"seed": p.seed, "truth": FILES["truth"], "other_force_file":
             FILES["mat" if p.force_file == "csv" else "csv"]}
    return top, {"mocap": mocap, "force": force, "pivot": {"file": FILES["pivot"]},
                 "synth": synth}


def _params_record(p: TwinParams) -> dict[str, object]:
    record = asdict(p)
    record["errors"] = asdict(p.errors)
    record["phantom"] = asdict(p.phantom)
    return record


def write_truth(path: str | Path, twin: Twin) -> None:
    """``truth.h5`` (data_schema.truth), validated after writing."""
    m, log, st, ind = twin.mocap, twin.log, twin.states, twin.indenter
    presses = twin.hand.presses
    rate = twin.params.rate_hz
    err = twin.params.errors
    noise = {"residual": "gamma-distributed length in a uniform random direction, independent "
                         "per sample", "mean_m": err.residual_mean, "sd_m": err.residual_sd}
    start = np.array([np.flatnonzero(m.press == k)[0] for k in range(len(presses))])
    end = np.array([np.flatnonzero(m.press == k)[-1] for k in range(len(presses))])
    peak = np.array([int(np.ceil(p.times[4] * rate - 1e-9)) for p in presses])
    data: dict[str, tuple[np.ndarray, str | None]] = {
        "point_names": (np.array([*PHANTOM_MARKERS, "tip"], dtype=object), None),
        "mocap/time_s": (m.time_s, "s"), "mocap/points": (m.points, "m"),
        "mocap/cluster": (m.cluster, "m"), "mocap/body_origin": (m.origin, "m"),
        "mocap/body_rotation": (m.rotation, "1"), "mocap/visible": (m.visible, "1"),
        "mocap/press": (m.press.astype(np.int32), "1"),
        "force/magnitude": (m.force, "N"), "force/lab": (m.force_lab, "N"),
        "force/sensor": (m.force_sensor, "N"), "force/torque_sensor": (m.torque_sensor, "N*m"),
        "logger/time_s": (log.time_s, "s"), "logger/mocap_time_s": (log.mocap_time_s, "s"),
        "logger/force": (log.force, "N"), "logger/torque": (log.torque, "N*m"),
        "logger/tool_force": (log.tool_force, "N"),
        "clock/offset_s": (np.float64(log.offset_s), "s"),
        "clock/drift_ppm": (np.float64(log.drift_ppm), "ppm"),
        "calibration/matrix": (twin.sensor.calibration.matrix, "N/V,N*m/V"),
        "calibration/bias": (twin.sensor.bias, "V"),
        "calibration/bias_drift": (twin.sensor.bias_drift, "V/s"),
        "calibration/quantum": (np.float64(twin.sensor.quantum), "V"),
        "calibration/noise": (np.float64(twin.sensor.noise), "V"),
        "indenter/markers": (ind.markers, "m"), "indenter/tip": (ind.tip, "m"),
        "indenter/sensor": (ind.sensor, "m"),
        "indenter/marker_names": (np.array(ind.names, dtype=object), None),
        "phantom/to_lab": (twin.to_lab, "m"), "phantom/rest_points": (m.points[0, :25], "m"),
        "locations/contact": (twin.contacts, "m"),
        "locations/node": (twin.nodes.astype(np.int32), "1"),
        "presses/location": (np.array([p.location for p in presses], np.int32), "1"),
        "presses/repeat": (np.array([p.repeat for p in presses], np.int32), "1"),
        "presses/direction": (np.array([p.direction for p in presses]), "1"),
        "presses/fmax": (np.array([p.fmax for p in presses]), "N"),
        "presses/start_frame": (start.astype(np.int64), "1"),
        "presses/peak_frame": (peak.astype(np.int64), "1"),
        "presses/end_frame": (end.astype(np.int64), "1"),
        "presses/times_s": (np.array([p.times for p in presses]), "s"),
        "states/points": (st.points, "m"), "states/force": (st.force, "N"),
        "states/force_vector": (st.force_vector, "N"),
        "states/step": (st.step.astype(np.int32), "1"),
        "states/press": (st.press.astype(np.int32), "1"),
        "states/location": (st.location.astype(np.int32), "1"),
        "states/time_s": (st.time_s, "s"),
        "pivot/point": (twin.pivot.point, "m"), "pivot/time_s": (twin.pivot.time_s, "s"),
        "pivot/cluster": (twin.pivot.cluster, "m"), "pivot/rotation": (twin.pivot.rotation, "1"),
    }
    if twin.params.trigger:
        scale = 1.0 + log.drift_ppm * 1e-6
        data["trigger/mocap_time_s"] = (log.pulses, "s")
        data["trigger/logger_time_s"] = (log.offset_s + scale * log.pulses, "s")
    provenance = make_provenance("synth", _params_record(twin.params), [], TRUTH.name,
                                 TRUTH.version)
    with h5py.File(path, "w", track_order=True) as f:
        f.attrs.update({
            "schema": TRUTH.name, "schema_version": TRUTH.version,
            "provenance": json.dumps(provenance), "seed": twin.params.seed,
            "rate_hz": rate, "logger_rate_hz": twin.params.logger_hz,
            "clock_convention": CLOCK_DOC, "units_length": "m", "units_force": "N",
            "units_time": "s", "noise_model": json.dumps(noise)})
        for name, (values, units) in data.items():
            big = np.ndim(values) > 0 and np.size(values) > 4096 and values.dtype != object
            ds = f.create_dataset(
                name, data=values, compression="gzip" if big else None,
                compression_opts=1 if big else None, shuffle=big,
                dtype=h5py.string_dtype() if values.dtype == object else None)
            if units is not None:
                ds.attrs["units"] = units
        f["clock/offset_s"].attrs["doc"] = CLOCK_DOC
        f["clock/drift_ppm"].attrs["doc"] = CLOCK_DOC
    validate_h5(path, TRUTH)

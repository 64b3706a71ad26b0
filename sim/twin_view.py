"""The synth recording: one press of the twin, the truth beside what the instruments delivered.

What a person checks: does the phantom surface deform sensibly under the tip, do the measured
markers (noisy, with gaps) scatter around the true ones, does the force the logger recorded
(calibrated with the true bias, put on the mocap clock with the true clock) follow the true
force, and where are the static states. One timeline, ``mocap_time`` (the twin's mocap clock),
over the press from the hover point to the retract.

Entities: ``phantom/surface`` (Mesh3D of the top surface, 50 Hz), ``truth/markers``,
``truth/tip``, ``truth/cluster`` (Points3D, 50 Hz), ``measured/markers``, ``measured/cluster``
(Points3D, 50 Hz, gaps left out), ``truth/states`` (static Points3D: the tip at every 0.5 N
state), ``force/truth`` and ``force/measured`` (Scalars, N: 500 Hz and 1 kHz), ``force/states``
(Scalars at the state times).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from core.recording import recording, time_column
from sim.twin import Twin

APP_ID = "phantom-synth"
VIEW_HZ = 50.0
TIMELINE = "mocap_time"
COLORS = {"truth": (40, 180, 90), "measured": (245, 140, 30), "surface": (140, 170, 220),
          "tip": (220, 40, 40)}
RADIUS_M = 0.0015


def blueprint() -> rrb.Blueprint:
    """The phantom in 3D on the left, the force over time on the right."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(name="phantom, markers and tip", origin="/",
                              contents=["+ /phantom/**", "+ /truth/**", "+ /measured/**"]),
            rrb.TimeSeriesView(name="force magnitude (N)", origin="/force"),
            column_shares=[3, 2],
        ),
        collapse_panels=False,
    )


def write_twin_recording(twin: Twin, path: str | Path, press: int = 0) -> None:
    """Save the recording of press ``press`` of ``twin`` to ``path`` (atomically)."""
    with recording(APP_ID, path, blueprint()) as rec:
        log_press(rec, twin, press)


def log_press(rec: rr.RecordingStream, twin: Twin, k: int) -> None:
    """Log press ``k``: surface, true and measured markers, tip, force and static states."""
    m = twin.mocap
    p = twin.hand.presses[k]
    window = np.flatnonzero((m.time_s >= p.times[1]) & (m.time_s <= p.times[7]))
    step = max(1, int(round(twin.params.rate_hz / VIEW_HZ)))
    frames = window[::step]
    ns = _ns(m.time_s[frames])
    _log_surface(rec, twin, k, frames, ns)
    _log_points(rec, "truth/markers", m.points[frames, :25], ns, COLORS["truth"])
    _log_points(rec, "truth/tip", m.points[frames, 25:], ns, COLORS["tip"], radius=0.002)
    _log_points(rec, "truth/cluster", m.cluster[frames], ns, COLORS["truth"])
    _log_points(rec, "measured/markers", m.measured[frames, :25], ns, COLORS["measured"])
    _log_points(rec, "measured/cluster", m.measured[frames, 25:], ns, COLORS["measured"])
    mine = twin.states.press == k
    rec.log("truth/states", rr.Points3D(twin.states.points[mine, 25], colors=[COLORS["tip"]],
                                        radii=[0.001]), static=True)
    _log_force(rec, twin, window, mine)


def _ns(time_s: np.ndarray) -> np.ndarray:
    return np.round(np.asarray(time_s) * 1e9).astype(np.int64)


def _log_points(rec: rr.RecordingStream, path: str, xyz: np.ndarray, ns: np.ndarray,
                color: tuple[int, int, int], radius: float = RADIUS_M) -> None:
    """Points per frame (T, N, 3); NaN points are left out of their frame."""
    rec.log(path, rr.Points3D.from_fields(colors=[color], radii=[radius]), static=True)
    ok = np.isfinite(xyz).all(axis=2)
    rec.send_columns(path, indexes=[time_column(TIMELINE, ns)],
                     columns=rr.Points3D.columns(positions=xyz[ok]).partition(ok.sum(axis=1)))


def _log_surface(rec: rr.RecordingStream, twin: Twin, k: int, frames: np.ndarray,
                 ns: np.ndarray) -> None:
    """The top surface as a triangle mesh, deformed by the press's force at each frame."""
    path = twin.paths[k]
    nx, ny = path.surface.shape[1:3]
    force = np.where(twin.mocap.press[frames] == k, twin.mocap.force[frames], 0.0)
    vertices = twin.lab(path.interpolate(force, "surface")).reshape(len(frames), nx * ny, 3)
    grid = np.arange(nx * ny).reshape(nx, ny)
    a, b, c, d = grid[:-1, :-1], grid[1:, :-1], grid[1:, 1:], grid[:-1, 1:]
    triangles = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                                np.stack([a, c, d], -1).reshape(-1, 3)])
    rec.log("phantom/surface", rr.Mesh3D.from_fields(triangle_indices=triangles,
                                                     albedo_factor=COLORS["surface"]),
            static=True)
    rec.send_columns("phantom/surface", indexes=[time_column(TIMELINE, ns)],
                     columns=rr.Mesh3D.columns(vertex_positions=vertices.reshape(-1, 3))
                     .partition(np.full(len(frames), nx * ny)))


def _log_force(rec: rr.RecordingStream, twin: Twin, window: np.ndarray,
               mine: np.ndarray) -> None:
    """True force at the frames; the logged force (true bias, matrix and clock) beside it."""
    m, log, sensor = twin.mocap, twin.log, twin.sensor
    rec.send_columns("force/truth", indexes=[time_column(TIMELINE, _ns(m.time_s[window]))],
                     columns=rr.Scalars.columns(scalars=m.force[window]))
    t0, t1 = m.time_s[window[0]], m.time_s[window[-1]]
    rows = np.flatnonzero((log.mocap_time_s >= t0) & (log.mocap_time_s <= t1))
    measured = np.linalg.norm(sensor.wrench(log.volts[rows], log.time_s[rows])[:, :3], axis=1)
    rec.send_columns("force/measured", indexes=[time_column(TIMELINE, _ns(log.mocap_time_s[rows]))],
                     columns=rr.Scalars.columns(scalars=measured))
    st = twin.states
    rec.send_columns("force/states", indexes=[time_column(TIMELINE, _ns(st.time_s[mine]))],
                     columns=rr.Scalars.columns(scalars=st.force[mine]))

"""The ingest recording: raw marker trajectories and the raw force log, each on its own clock.

What a person checks after ingest: are the named markers where they should be (phantom markers
blue, indenter cluster orange, any other marker grey), where are the gaps, and does the force
log look sane. One timeline, ``device_time``: each stream on its own device's clock, as it was
recorded (mocap frames, logger samples, the pivot trial); they are not aligned yet, that is the
sync stage's job, and the views' names say which clock they show. +z is up and the camera
frames the phantom's markers.

Entities: ``mocap/{phantom,indenter,other}/<marker>`` (Points3D, at most :data:`VIEW_HZ`
frames per second; a frame is left out when its decimation window holds a gap, so even a
one-sample gap shows; entity names are the marker names made path-safe, the label keeps the
name), ``trails/{phantom,indenter,other}`` (static LineStrips3D of every marker's path, broken
at gaps, thin and faded under the current markers), ``mocap/bodies/<body>`` (6D body origins),
``mocap/events`` (TextLog of the export's EVENT lines), ``quality/missing_markers`` (named
markers missing in each frame), ``force/<unit>/<channel>`` (one plot per unit: gauge volts, or
forces in N and torques in N m; one colour per channel), ``trigger/level`` (V, its own plot)
and ``pivot/indenter/<marker>`` (the pivot trial, its own view).
"""

from __future__ import annotations

import re
import warnings
from math import ceil
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from core.recording import declare_up, phantom_view, plot, recording, send_series, time_column
from core.series import MarkerSeries, RawSession

APP_ID = "phantom-ingest"
TIMELINE = "device_time"
VIEW_HZ = 50.0           # 3D points per marker per second of recording, at most
TRAIL_HZ = 10.0          # vertices per second of the static trails
COLORS = {"phantom": (60, 140, 230), "indenter": (245, 140, 30), "other": (150, 150, 150),
          "bodies": (220, 60, 60), "missing": (230, 80, 80), "trigger": (200, 200, 200)}
TRAIL_ALPHA = 70         # trails faded, so the current markers stand out on them
CHANNEL_COLORS = [(214, 39, 40), (44, 160, 44), (31, 119, 180), (255, 127, 14),
                  (148, 103, 189), (23, 190, 207)]
RADIUS_M = 0.0015        # the phantom's 3 mm marker spheres
UNIT_NAMES = {"V": "gauge voltages [V]", "N": "force [N]", "N*m": "torque [N m]"}


def blueprint(s: RawSession) -> rrb.Blueprint:
    """3D markers (and the pivot trial) on the left; force log, trigger, missing markers and
    events on the right, one plot per unit."""
    centre, size = _frame(s)
    left = [phantom_view("markers (mocap clock): phantom blue, indenter orange, other grey",
                         ["+ /mocap/**", "+ /trails/**"], centre, size)]
    if s.pivot is not None:
        pc, ps = _extent(s.pivot.positions)
        left.append(phantom_view("pivot trial (its own clock)", ["+ /pivot/**"], pc, ps))
    right: list[rrb.View] = [plot(f"{UNIT_NAMES.get(u, f'[{u}]')} (force logger clock)",
                                  f"/force/{_part(u)}") for u in dict.fromkeys(s.force.units)]
    if s.force.trigger is not None:
        right.append(plot("trigger [V] (force logger clock)", "/trigger", legend=False))
    right += [plot("named markers missing per frame (mocap clock)", "/quality", legend=False),
              rrb.TextLogView(name="events (mocap clock)", origin="/mocap/events")]
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Vertical(*left, row_shares=[3, 1][:len(left)]),
                       rrb.Vertical(*right), column_shares=[3, 2]),
        collapse_panels=False,
    )


def write_ingest_recording(session: RawSession, path: str | Path) -> None:
    """Save the ingest recording of ``session`` to ``path`` (atomically)."""
    with recording(APP_ID, path, blueprint(session)) as rec:
        declare_up(rec)
        log_session(rec, session)


def log_session(rec: rr.RecordingStream, s: RawSession) -> None:
    """Log every stream of a raw session."""
    groups = _groups(s)
    finite = _finite(s.markers.positions)
    _log_markers(rec, s.markers, finite, "mocap", groups)
    _log_trails(rec, s.markers, finite, groups)
    _log_missing(rec, s.markers, finite, s.phantom_markers + s.indenter_markers)
    if s.markers.events:
        times = np.array([t for _, t in s.markers.events], dtype=np.int64)
        rec.send_columns("mocap/events", indexes=[time_column(TIMELINE, times)],
                         columns=rr.TextLog.columns(text=[e for e, _ in s.markers.events]))
    if s.bodies is not None:
        b = s.bodies
        ok = _window_ok(_finite(b.positions), _stride(b.rate_hz, VIEW_HZ))
        for i, name in enumerate(b.bodies):
            _log_points(rec, f"mocap/bodies/{_part(name)}", name, b.time_ns, b.positions[:, i],
                        ok[:, i], b.rate_hz, COLORS["bodies"])
    if s.pivot is not None:
        _log_markers(rec, s.pivot, _finite(s.pivot.positions), "pivot",
                     dict.fromkeys(s.pivot.labels, "indenter"))
    _log_force(rec, s)


def _extent(positions: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and size (m) of the points' median positions, for a camera."""
    with warnings.catch_warnings():          # a marker never seen has no median: NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        rest = np.nanmedian(positions, axis=0) if positions.size else np.zeros((1, 3))
    rest = rest[np.isfinite(rest).all(axis=1)]
    if not len(rest):
        return np.zeros(3), 0.2
    return rest.mean(axis=0), max(float(np.ptp(rest, axis=0)[:2].max()) * 1.25, 0.05)


def _frame(s: RawSession) -> tuple[np.ndarray, float]:
    """Centre and size of the phantom's markers (all markers when none is named)."""
    cols = [i for i, n in enumerate(s.markers.labels) if n in set(s.phantom_markers)]
    centre, size = _extent(s.markers.positions[:, cols] if cols else s.markers.positions)
    return centre, 1.8 * size                 # room for the indenter above the phantom


def _groups(s: RawSession) -> dict[str, str]:
    return {**dict.fromkeys(s.phantom_markers, "phantom"),
            **dict.fromkeys(s.indenter_markers, "indenter")}


def _part(name: str) -> str:
    """A marker or unit name as an entity path part without escapes (the label keeps it)."""
    return re.sub(r"[^A-Za-z0-9_-]+", "_", name).strip("_") or "_"


def _finite(positions: np.ndarray) -> np.ndarray:
    """``(T, M)``: the point has a position in that frame."""
    return ~np.isnan(positions).any(axis=2)


def _stride(rate_hz: float, hz: float) -> int:
    return max(1, ceil(rate_hz / hz)) if np.isfinite(rate_hz) and rate_hz > 0 else 1


def _window_ok(finite: np.ndarray, stride: int) -> np.ndarray:
    """Per decimation window (rows of ``x[::stride]``): no gap anywhere in the window."""
    n = finite.shape[0]
    windows = -(-n // stride)
    padded = np.ones((windows * stride, *finite.shape[1:]), dtype=bool)
    padded[:n] = finite
    return np.asarray(padded.reshape(windows, stride, *finite.shape[1:]).all(axis=1))


def _log_markers(rec: rr.RecordingStream, m: MarkerSeries, finite: np.ndarray, root: str,
                 groups: dict[str, str]) -> None:
    ok = _window_ok(finite, _stride(m.rate_hz, VIEW_HZ))
    for i, (name, part) in enumerate(zip(m.labels, _unique_parts(m.labels), strict=True)):
        group = groups.get(name, "other")
        _log_points(rec, f"{root}/{group}/{part}", name, m.time_ns, m.positions[:, i],
                    ok[:, i], m.rate_hz, COLORS[group])


def _unique_parts(names: list[str]) -> list[str]:
    """Path-safe names, a suffix added where two names become one ("P 1", "P_1")."""
    seen: dict[str, int] = {}
    out = []
    for name in names:
        part = _part(name)
        seen[part] = seen.get(part, 0) + 1
        out.append(part if seen[part] == 1 else f"{part}_{seen[part]}")
    return out


def _log_points(rec: rr.RecordingStream, path: str, label: str, time_ns: np.ndarray,
                xyz: np.ndarray, ok: np.ndarray, rate_hz: float,
                color: tuple[int, int, int]) -> None:
    """One point per decimation window (VIEW_HZ) that has no gap (``ok``)."""
    rec.log(path, rr.Points3D.from_fields(colors=[color], radii=[RADIUS_M], labels=[label],
                                          show_labels=False), static=True)
    rows = np.flatnonzero(ok) * _stride(rate_hz, VIEW_HZ)
    if rows.size:
        rec.send_columns(path, indexes=[time_column(TIMELINE, time_ns[rows])],
                         columns=rr.Points3D.columns(positions=xyz[rows]))


def _log_trails(rec: rr.RecordingStream, m: MarkerSeries, finite: np.ndarray,
                groups: dict[str, str]) -> None:
    """Each marker's whole path as thin, faded line strips, broken wherever a decimation window
    has a gap."""
    stride = _stride(m.rate_hz, TRAIL_HZ)
    ok = _window_ok(finite, stride)                                       # (W, M)
    sampled = m.positions[::stride]
    strips: dict[str, list[np.ndarray]] = {}
    for i, name in enumerate(m.labels):
        edges = np.diff(np.concatenate(([0], ok[:, i].astype(np.int8), [0])))
        starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        strips.setdefault(groups.get(name, "other"), []).extend(
            sampled[a:b, i] for a, b in zip(starts, stops, strict=True) if b - a > 1)
    for group, lines in strips.items():
        if lines:
            rec.log(f"trails/{group}", rr.LineStrips3D(
                lines, colors=[(*COLORS[group], TRAIL_ALPHA)], radii=[RADIUS_M / 6]),
                static=True)


def _log_missing(rec: rr.RecordingStream, m: MarkerSeries, finite: np.ndarray,
                 named: list[str]) -> None:
    index = {n: i for i, n in enumerate(m.labels)}
    cols = [index[n] for n in named if n in index]
    missing = len(cols) - finite[:, cols].sum(axis=1, dtype=np.int64)
    send_series(rec, "quality/missing_markers", TIMELINE, m.time_ns, missing,
                "named markers missing", COLORS["missing"])


def _log_force(rec: rr.RecordingStream, s: RawSession) -> None:
    """Each channel a named, coloured series under its unit's plot; the trigger apart."""
    f = s.force
    for i, (channel, unit) in enumerate(zip(f.channels, f.units, strict=True)):
        send_series(rec, f"force/{_part(unit)}/{_part(channel)}", TIMELINE, f.time_ns,
                    f.values[:, i], channel, CHANNEL_COLORS[i % len(CHANNEL_COLORS)], width=1.0)
    if f.trigger is not None:
        send_series(rec, "trigger/level", TIMELINE, f.time_ns, f.trigger, "trigger",
                    COLORS["trigger"], width=1.0)

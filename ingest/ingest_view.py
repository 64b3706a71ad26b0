"""The ingest recording: raw marker trajectories and the raw force log, each on its own clock.

What a person checks after ingest: are the named markers where they should be (phantom markers
blue, indenter cluster orange, any other marker grey), where are the gaps, and does the force
log look sane. Timelines: ``mocap_time`` (mocap clock), ``force_time`` (force logger clock),
``pivot_time`` (pivot recording); they are not aligned yet, that is the sync stage's job.

Entities: ``mocap/{phantom,indenter,other}/<marker>`` (Points3D over ``mocap_time``, at most
:data:`VIEW_HZ` frames per second; a frame is left out when its decimation window holds a gap,
so even a one-sample gap shows), ``trails/{phantom,indenter,other}`` (static LineStrips3D of
every marker's path, broken at gaps), ``mocap/bodies/<body>`` (6D body origins),
``mocap/events`` (TextLog of the export's EVENT lines), ``quality/missing_markers`` (Scalars:
named markers missing in each frame, full rate), ``force/raw`` (Scalars, six series, full
rate, over ``force_time``), ``force/trigger`` and ``pivot/indenter/<marker>``.
"""

from __future__ import annotations

from math import ceil
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from core.recording import recording, time_column
from core.series import MarkerSeries, RawSession

APP_ID = "phantom-ingest"
VIEW_HZ = 50.0           # 3D points per marker per second of recording, at most
TRAIL_HZ = 10.0          # vertices per second of the static trails
COLORS = {"phantom": (60, 140, 230), "indenter": (245, 140, 30), "other": (150, 150, 150),
          "bodies": (220, 60, 60)}
RADIUS_M = 0.0015        # the phantom's 3 mm marker spheres


def blueprint() -> rrb.Blueprint:
    """3D markers and trails on the left; force log and missing-marker counts on the right."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(name="markers (mocap clock)", origin="/",
                              contents=["+ /mocap/**", "+ /trails/**", "+ /pivot/**"]),
            rrb.Vertical(
                rrb.TimeSeriesView(name="force log (force clock)", origin="/force"),
                rrb.TimeSeriesView(name="missing markers (mocap clock)", origin="/quality"),
                rrb.TextLogView(name="events", origin="/mocap/events"),
                row_shares=[3, 2, 1],
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=False,
    )


def write_ingest_recording(session: RawSession, path: str | Path) -> None:
    """Save the ingest recording of ``session`` to ``path`` (atomically)."""
    with recording(APP_ID, path, blueprint()) as rec:
        log_session(rec, session)


def log_session(rec: rr.RecordingStream, s: RawSession) -> None:
    """Log every stream of a raw session."""
    groups = _groups(s)
    finite = _finite(s.markers.positions)
    _log_markers(rec, s.markers, finite, "mocap", "mocap_time", groups)
    _log_trails(rec, s.markers, finite, groups)
    _log_missing(rec, s.markers, finite, s.phantom_markers + s.indenter_markers)
    if s.markers.events:
        times = np.array([t for _, t in s.markers.events], dtype=np.int64)
        rec.send_columns("mocap/events", indexes=[time_column("mocap_time", times)],
                         columns=rr.TextLog.columns(text=[e for e, _ in s.markers.events]))
    if s.bodies is not None:
        b = s.bodies
        ok = _window_ok(_finite(b.positions), _stride(b.rate_hz, VIEW_HZ))
        for i, name in enumerate(b.bodies):
            _log_points(rec, f"mocap/bodies/{_part(name)}", name, b.time_ns, b.positions[:, i],
                        ok[:, i], b.rate_hz, "mocap_time", COLORS["bodies"])
    if s.pivot is not None:
        _log_markers(rec, s.pivot, _finite(s.pivot.positions), "pivot", "pivot_time",
                     dict.fromkeys(s.pivot.labels, "indenter"))
    _log_force(rec, s)


def _groups(s: RawSession) -> dict[str, str]:
    return {**dict.fromkeys(s.phantom_markers, "phantom"),
            **dict.fromkeys(s.indenter_markers, "indenter")}


def _part(name: str) -> str:
    return rr.escape_entity_path_part(name)


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
    return padded.reshape(windows, stride, *finite.shape[1:]).all(axis=1)


def _log_markers(rec: rr.RecordingStream, m: MarkerSeries, finite: np.ndarray, root: str,
                 timeline: str, groups: dict[str, str]) -> None:
    ok = _window_ok(finite, _stride(m.rate_hz, VIEW_HZ))
    for i, name in enumerate(m.labels):
        group = groups.get(name, "other")
        _log_points(rec, f"{root}/{group}/{_part(name)}", name, m.time_ns, m.positions[:, i],
                    ok[:, i], m.rate_hz, timeline, COLORS[group])


def _log_points(rec: rr.RecordingStream, path: str, label: str, time_ns: np.ndarray,
                xyz: np.ndarray, ok: np.ndarray, rate_hz: float, timeline: str,
                color: tuple[int, int, int]) -> None:
    """One point per decimation window (VIEW_HZ) that has no gap (``ok``)."""
    rec.log(path, rr.Points3D.from_fields(colors=[color], radii=[RADIUS_M], labels=[label],
                                          show_labels=False), static=True)
    rows = np.flatnonzero(ok) * _stride(rate_hz, VIEW_HZ)
    if rows.size:
        rec.send_columns(path, indexes=[time_column(timeline, time_ns[rows])],
                         columns=rr.Points3D.columns(positions=xyz[rows]))


def _log_trails(rec: rr.RecordingStream, m: MarkerSeries, finite: np.ndarray,
                groups: dict[str, str]) -> None:
    """Each marker's whole path as line strips, broken wherever a decimation window has a gap."""
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
            rec.log(f"trails/{group}", rr.LineStrips3D(lines, colors=[COLORS[group]],
                                                       radii=[RADIUS_M / 4]), static=True)


def _log_missing(rec: rr.RecordingStream, m: MarkerSeries, finite: np.ndarray,
                 named: list[str]) -> None:
    index = {n: i for i, n in enumerate(m.labels)}
    cols = [index[n] for n in named if n in index]
    missing = len(cols) - finite[:, cols].sum(axis=1, dtype=np.int64)
    rec.log("quality/missing_markers", rr.SeriesLines(names=["named markers missing"]),
            static=True)
    rec.send_columns("quality/missing_markers", indexes=[time_column("mocap_time", m.time_ns)],
                     columns=rr.Scalars.columns(scalars=missing.astype(np.float64)))


def _log_force(rec: rr.RecordingStream, s: RawSession) -> None:
    f = s.force
    names = [f"{c} [{u}]" for c, u in zip(f.channels, f.units, strict=True)]
    rec.log("force/raw", rr.SeriesLines(names=names), static=True)
    rec.send_columns("force/raw", indexes=[time_column("force_time", f.time_ns)],
                     columns=rr.Scalars.columns(scalars=f.values).partition(
                         np.full(f.frames, f.values.shape[1])))
    if f.trigger is not None:
        rec.log("force/trigger", rr.SeriesLines(names=["trigger"]), static=True)
        rec.send_columns("force/trigger", indexes=[time_column("force_time", f.time_ns)],
                         columns=rr.Scalars.columns(scalars=f.trigger))

"""The extract recording: where on each press's force curve were the states read, and what do
they look like in the phantom frame?

Timeline ``session_time`` (the mocap clock; several sessions follow one another, 1 s apart).
Entities: ``force/measured`` the force magnitude of every press (N), ``force/levels`` a point
at each extracted state (at the instant it was read, at its force); ``phantom/state`` the
markers of the latest state (coloured by depth below the rest surface, mm), ``phantom/tip`` the
tip, ``phantom/rest`` the press's untouched surface (grey), ``phantom/footprint`` the phantom's
outline at z = 0, or a curved phantom's ``phantom/shape`` (its mould, translucent: the frame is
the mould's, and the colour is each marker's displacement from its rest, mm); ``presses`` a
text line per press.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from core.recording import declare_up, log_mould, phantom_view, recording, time_column
from data_schema.shape import Shape
from extract.static_states import PressSeries, PressStates

APP_ID = "phantom-extract"
TIMELINE = "session_time"
COLORS = {"force": (90, 90, 90), "levels": (230, 60, 40), "tip": (220, 40, 40),
          "rest": (150, 150, 150), "outline": (200, 200, 200)}
DEPTH_RANGE_MM = 15.0


def blueprint(size_m: tuple[float, float], centre: np.ndarray | None = None) -> rrb.Blueprint:
    """The states in 3D (framed from above, on ``centre``: the footprint's middle by
    default) beside the force curve with the levels marked."""
    colour = "depth" if centre is None else "displacement"
    centre = np.array([size_m[0] / 2, size_m[1] / 2, 0.0]) if centre is None else centre
    return rrb.Blueprint(
        rrb.Horizontal(
            phantom_view(f"state in the phantom frame (colour: {colour} 0..."
                         f"{DEPTH_RANGE_MM:.0f} mm)", ["+ /phantom/**"], centre,
                         max(size_m), origin="/phantom"),
            rrb.Vertical(
                rrb.TimeSeriesView(name="force magnitude [N], extracted levels", origin="/force"),
                rrb.TextLogView(name="presses", origin="/presses"),
                row_shares=[4, 1],
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


def write_extract_recording(path: str | Path,
                            sessions: list[tuple[list[PressSeries], list[PressStates]]],
                            size_m: tuple[float, float], shape: Shape | None = None) -> None:
    """Save the recording of every session's presses and states to ``path`` (``shape``: a
    curved phantom's, drawn instead of the flat footprint)."""
    centre = None if shape is None else shape.vertices.mean(axis=0)
    with recording(APP_ID, path, blueprint(size_m, centre)) as rec:
        declare_up(rec)
        if shape is None:
            _outline(rec, size_m)
        else:
            log_mould(rec, "phantom/shape", shape.vertices, shape.faces)
        offset, k = 0.0, 0
        for presses, states in sessions:
            start = min(p.time_s[0] for p in presses)
            for press, st in zip(presses, states, strict=True):
                _press(rec, press, st, offset - start, k, shape is not None)
                k += 1
            offset += max(p.time_s[-1] for p in presses) - start + 1.0


def _ns(t: np.ndarray) -> np.ndarray:
    return np.round(np.asarray(t) * 1e9).astype(np.int64)


def _press(rec: rr.RecordingStream, press: PressSeries, st: PressStates, shift: float, k: int,
           curved: bool) -> None:
    t = press.time_s + shift
    rec.log("force/measured", rr.SeriesLines(names=["force [N]"], colors=[COLORS["force"]]),
            static=True)
    rec.send_columns("force/measured", indexes=[time_column(TIMELINE, _ns(t))],
                     columns=rr.Scalars.columns(scalars=press.force))
    rec.set_time(TIMELINE, duration=np.timedelta64(int(_ns(t[press.onset])), "ns"))
    rec.log("presses", rr.TextLog(f"press {k}: {len(st.step)} states, levels "
                                  f"0..{st.step.max() if len(st.step) else '-'}"))
    if not len(st.step):
        return
    rec.log("force/levels", rr.SeriesPoints(names=["extracted level [N]"],
                                            colors=[COLORS["levels"]], marker_sizes=[4]),
            static=True)
    rec.send_columns("force/levels", indexes=[time_column(TIMELINE, _ns(st.time_s + shift))],
                     columns=rr.Scalars.columns(scalars=st.force))
    rest = st.points[0] if st.step[0] == 0 else None
    for i in range(len(st.step)):
        rec.set_time(TIMELINE, duration=np.timedelta64(int(_ns(st.time_s[i] + shift)), "ns"))
        _state(rec, st.points[i], st.valid[i], rest, curved)


def _state(rec: rr.RecordingStream, points: np.ndarray, valid: np.ndarray,
           rest: np.ndarray | None, curved: bool) -> None:
    surface, ok = points[:-1], valid[:-1]
    if not curved:
        depth = np.clip(-surface[ok, 2] * 1e3 / DEPTH_RANGE_MM, 0, 1)
    else:              # no plane to be below: how far each marker moved from its rest
        moved = np.zeros(len(surface)) if rest is None else np.linalg.norm(surface - rest[:-1],
                                                                           axis=1)
        depth = np.clip(np.nan_to_num(moved[ok]) * 1e3 / DEPTH_RANGE_MM, 0, 1)
    colors = (np.array([[40, 120, 230]]) * (1 - depth[:, None])
              + np.array([[240, 200, 30]]) * depth[:, None]).astype(np.uint8)
    rec.log("phantom/state", rr.Points3D(surface[ok], colors=colors, radii=[0.0015]))
    if valid[-1]:
        rec.log("phantom/tip", rr.Points3D(points[-1:], colors=[COLORS["tip"]], radii=[0.002]))
    if rest is not None:
        good = np.isfinite(rest[:-1]).all(axis=1)
        rec.log("phantom/rest", rr.Points3D(rest[:-1][good], colors=[COLORS["rest"]],
                                            radii=[0.0008]))


def _outline(rec: rr.RecordingStream, size_m: tuple[float, float]) -> None:
    w, h = size_m
    corners = np.array([[0, 0, 0], [w, 0, 0], [w, h, 0], [0, h, 0], [0, 0, 0]], float)
    rec.log("phantom/footprint", rr.LineStrips3D([corners], colors=[COLORS["outline"]],
                                                 radii=[0.0003]), static=True)

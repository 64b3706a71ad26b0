"""The sync recording: does the force line up with the tip's motion, and where is the tip?

Timeline ``mocap_time`` (the mocap clock, the synced files' time base). Entities:

* ``before/force_magnitude``, ``before/depth_mm``: force magnitude read with the logger clock
  taken as the mocap clock (no alignment), beside the tip depth; ``after/force_magnitude``,
  ``after/depth_mm``: the same after clock alignment (Scalars, full rate);
* ``force_vs_depth/before``, ``force_vs_depth/after``: force (N) over tip depth (mm) as 2D
  points; aligned, loading and unloading fall on one curve, unaligned they open a loop;
* ``scene/phantom``, ``scene/tip``, ``scene/cluster``: the 25 phantom markers, the tip and the
  indenter markers in 3D (at most :data:`VIEW_HZ` frames per second), gap-filled samples
  orange; ``scene/tip_path``: the tip's path (static);
* ``quality/filled``, ``quality/missing``: points filled or missing per frame (Scalars);
* ``presses``: a TextLog line at each contact onset (press, location, repeat).
"""

from __future__ import annotations

from math import ceil
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from calib.gaps import FILLED, MISSING
from calib.sync import SyncResult
from core.recording import recording, time_column

APP_ID = "phantom-sync"
VIEW_HZ = 50.0
SCATTER_MAX = 20000          # 2D points per force-vs-depth cloud, at most
COLORS = {"phantom": (60, 140, 230), "tip": (220, 40, 40), "cluster": (245, 140, 30),
          "filled": (255, 190, 0), "before": (150, 150, 150), "after": (40, 160, 80)}
RADIUS_M = 0.0015


def blueprint() -> rrb.Blueprint:
    """3D scene on the left; force and depth before/after alignment on the right."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(name="phantom, tip and indenter", origin="/scene"),
            rrb.Vertical(
                rrb.TimeSeriesView(name="before alignment: force [N], depth [mm]",
                                   origin="/before"),
                rrb.TimeSeriesView(name="after alignment: force [N], depth [mm]",
                                   origin="/after"),
                rrb.Spatial2DView(name="force [N] over tip depth [mm]",
                                  origin="/force_vs_depth"),
                rrb.TimeSeriesView(name="points filled / missing", origin="/quality"),
                rrb.TextLogView(name="presses", origin="/presses"),
                row_shares=[2, 2, 3, 1, 1],
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=False,
    )


def write_sync_recording(result: SyncResult, path: str | Path) -> None:
    """Save the sync recording of ``result`` to ``path`` (atomically)."""
    with recording(APP_ID, path, blueprint()) as rec:
        log_sync(rec, result)


def log_sync(rec: rr.RecordingStream, r: SyncResult) -> None:
    """Log the alignment, the scene, the quality counts and the presses."""
    s = r.session
    t = s["time_ns"]
    depth_mm = s["depth"] * 1e3
    for stage, force in (("before", s["force_magnitude_unaligned"]),
                         ("after", s["force_magnitude"])):
        _series(rec, f"{stage}/force_magnitude", t, force, "force magnitude [N]",
                COLORS[stage])
        _series(rec, f"{stage}/depth_mm", t, depth_mm, "tip depth [mm]", COLORS["tip"])
        _scatter(rec, f"force_vs_depth/{stage}", depth_mm, force, COLORS[stage])
    q = s["quality"]
    _series(rec, "quality/filled", t, ((q & FILLED) > 0).sum(axis=1), "filled", COLORS["filled"])
    _series(rec, "quality/missing", t, ((q & MISSING) > 0).sum(axis=1), "missing",
            COLORS["before"])
    stride = max(1, ceil(r.rate_hz / VIEW_HZ))
    rows = np.arange(0, len(t), stride)
    filled = (q[rows] & FILLED) > 0
    _points(rec, "scene/phantom", t[rows], s["points"][rows, :-1], filled[:, :-1],
            COLORS["phantom"])
    _points(rec, "scene/tip", t[rows], s["points"][rows, -1:], filled[:, -1:], COLORS["tip"])
    _points(rec, "scene/cluster", t[rows], s["cluster"][rows],
            np.zeros(s["cluster"][rows].shape[:2], bool), COLORS["cluster"])
    tip = s["tip"][rows]
    tip = tip[np.isfinite(tip).all(axis=1)]
    if len(tip) > 1:
        rec.log("scene/tip_path", rr.LineStrips3D([tip], colors=[COLORS["tip"]],
                                                  radii=[RADIUS_M / 4]), static=True)
    _presses(rec, r)


def _series(rec: rr.RecordingStream, path: str, t: np.ndarray, y: np.ndarray, name: str,
            color: tuple[int, int, int]) -> None:
    rec.log(path, rr.SeriesLines(names=[name], colors=[color]), static=True)
    rec.send_columns(path, indexes=[time_column("mocap_time", t)],
                     columns=rr.Scalars.columns(scalars=np.asarray(y, np.float64)))


def _scatter(rec: rr.RecordingStream, path: str, x: np.ndarray, y: np.ndarray,
             color: tuple[int, int, int]) -> None:
    ok = np.flatnonzero(np.isfinite(x) & np.isfinite(y) & (y > 0.02))
    ok = ok[:: max(1, ceil(len(ok) / SCATTER_MAX))]
    # 2D views draw y downwards: plot -force so that larger force is higher up
    pos = np.stack([x[ok], -y[ok]], axis=1)
    rec.log(path, rr.Points2D(pos, colors=[color], radii=[0.02]), static=True)


def _points(rec: rr.RecordingStream, path: str, t: np.ndarray, xyz: np.ndarray,
            filled: np.ndarray, color: tuple[int, int, int]) -> None:
    """Points per frame (NaN ones left out), filled samples in the 'filled' colour."""
    ok = np.isfinite(xyz).all(axis=2)
    colors = np.where(filled[..., None], COLORS["filled"], color).astype(np.uint8)
    rec.log(path, rr.Points3D.from_fields(radii=[RADIUS_M]), static=True)
    rec.send_columns(path, indexes=[time_column("mocap_time", t)],
                     columns=rr.Points3D.columns(positions=xyz[ok], colors=colors[ok])
                     .partition(ok.sum(axis=1)))


def _presses(rec: rr.RecordingStream, r: SyncResult) -> None:
    if not r.presses:
        return
    times = np.array([p.time_ns[p.press.onset] for p in r.presses], np.int64)
    text = [f"press {k}: location {p.press.location}, repeat {p.press.repeat}, peak "
            f"{p.force_magnitude[p.press.peak]:.2f} N" for k, p in enumerate(r.presses)]
    rec.send_columns("presses", indexes=[time_column("mocap_time", times)],
                     columns=rr.TextLog.columns(text=text))

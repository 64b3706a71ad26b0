"""The sync recording: does the force line up with the tip's motion, and where is the tip?

One timeline, ``mocap_time`` (the mocap clock, the synced files' time base); +z is up and the
camera frames the phantom. Entities:

* ``force/before``, ``force/after``: force magnitude read with the logger clock taken as the
  mocap clock (no alignment, grey) and after clock alignment (green), N, one plot;
* ``depth/tip``: the tip's depth below the phantom's rest surface (mm; negative above it);
* ``force_vs_depth``: a static plot image of force (N) over tip depth (mm), before and after:
  aligned, loading and unloading fall on one curve, unaligned they open a loop;
* ``scene/surface``: the phantom's surface through its markers as a wire mesh
  (LineStrips3D, 50 Hz), coloured by how far the markers have moved from their rest positions
  (viridis, range in the view's name);
  ``scene/phantom`` (blue) and ``scene/cluster`` (orange) markers, gap-filled samples yellow;
  ``scene/tip`` (large red ball), ``scene/shaft`` (the indenter from the tip to its markers),
  ``scene/tip_path`` (the whole path, faint, static);
* a curved phantom's ``scene/shape`` (its mould's surface where the markers registered it,
  translucent, static) and ``scene/residual`` (each marker at rest, labelled with how far it
  rests off that surface, coloured 0 .. 0.3 mm);
* ``quality/filled``, ``quality/missing``: points filled or missing per frame;
  ``quality/saturated``, ``quality/over_range``: 1 where the force was read from a gauge on the
  amplifier's rail or lies beyond the sensor's rating (extract leaves those presses out);
  ``quality/hole``: 1 on the frames a hole in either stream reaches (mocap frames never
  recorded, or force resampled from a hole's edge: :mod:`sync.holes`);
* ``presses``: a TextLog line at each contact onset (press, location, repeat, peak), and a
  warning at each hole (its stream, length, and the presses it cost): clicking one moves
  every view there.
"""

from __future__ import annotations

import io
import warnings
from math import ceil
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from scipy.spatial import Delaunay

from calib.shape_registration import Registration
from core.recording import (
    colormap,
    declare_up,
    log_mould,
    phantom_view,
    plot,
    recording,
    send_series,
    time_column,
)
from core.text import count
from data_schema.phantom import PhantomLayout
from data_schema.synced import FORCE_BITS
from sync.gaps import FILLED, MISSING
from sync.sync import SyncResult

APP_ID = "phantom-sync"
TIMELINE = "mocap_time"
VIEW_HZ = 50.0
SCATTER_MAX = 20000          # points per force-vs-depth cloud, at most
COLORS = {"phantom": (60, 140, 230), "tip": (230, 30, 30), "cluster": (245, 140, 30),
          "filled": (255, 220, 0), "before": (150, 150, 150), "after": (40, 170, 80),
          "depth": (200, 120, 230), "path": (255, 160, 160, 90), "shaft": (200, 200, 200),
          "missing": (150, 150, 150), "saturated": (230, 30, 30), "over_range": (140, 0, 140),
          "hole": (0, 200, 255)}
FLAG_NAMES = {"saturated": "force on the amplifier's rail", "over_range": "force beyond rating"}
RADIUS_M = 0.0015
RESIDUAL_SCALE_M = 0.3e-3    # a registration residual coloured at the top of the map


def blueprint(centre: np.ndarray, size: float, moved_mm: float) -> rrb.Blueprint:
    """The scene on the left; force, depth, force over depth and quality on the right."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                phantom_view(f"phantom (marker displacement 0 .. {moved_mm:.0f} mm), tip red, "
                             "gap-filled yellow", ["+ /scene/**"], centre, size),
                rrb.TextLogView(name="presses (click one to go there)", origin="/presses"),
                row_shares=[5, 1],
            ),
            rrb.Vertical(
                plot("force magnitude [N]: before alignment grey, after green", "/force"),
                plot("tip depth below the rest surface [mm]", "/depth", legend=False),
                rrb.Spatial2DView(name="force over tip depth, before and after alignment",
                                  origin="/force_vs_depth"),
                plot("per frame: points filled, missing; force on rail, over range; hole",
                     "/quality"),
                row_shares=[3, 2, 4, 2],
            ),
            column_shares=[1, 1],
        ),
        collapse_panels=False,
    )


def write_sync_recording(result: SyncResult, path: str | Path) -> None:
    """Save the sync recording of ``result`` to ``path`` (atomically)."""
    s = result.session
    rest = _rest(s["points"][:, :-1])
    moved = np.linalg.norm(s["points"][:, :-1] - rest, axis=2)
    scale = float(np.nanpercentile(moved, 99.9)) if np.isfinite(moved).any() else 0.0
    ok = np.isfinite(rest).all(axis=1)
    size = float(np.ptp(rest[ok], axis=0)[:2].max()) * 1.25 if ok.sum() > 1 else 0.1
    centre = rest[ok].mean(axis=0) if ok.any() else np.zeros(3)
    with recording(APP_ID, path, blueprint(centre, size, scale * 1e3)) as rec:
        declare_up(rec)
        log_sync(rec, result, rest, max(scale, 1e-9))


def log_sync(rec: rr.RecordingStream, r: SyncResult, rest: np.ndarray, scale: float) -> None:
    """Log the alignment, the scene, the quality counts and the presses."""
    s = r.session
    t = s["time_ns"]
    for stage in ("before", "after"):
        force = s["force_magnitude_unaligned" if stage == "before" else "force_magnitude"]
        send_series(rec, f"force/{stage}", TIMELINE, t, force, f"{stage} alignment",
                    COLORS[stage], width=1.0 if stage == "before" else 2.0)
    send_series(rec, "depth/tip", TIMELINE, t, s["depth"] * 1e3, "tip depth", COLORS["depth"])
    rec.log("force_vs_depth", rr.EncodedImage(contents=force_depth_png(s),
                                              media_type="image/png"), static=True)
    q = s["quality"]
    send_series(rec, "quality/filled", TIMELINE, t, ((q & FILLED) > 0).sum(axis=1),
                "gap-filled points", COLORS["filled"])
    send_series(rec, "quality/missing", TIMELINE, t, ((q & MISSING) > 0).sum(axis=1),
                "missing points", COLORS["missing"])
    for bit in ("saturated", "over_range"):       # extract leaves these presses out
        send_series(rec, f"quality/{bit}", TIMELINE, t,
                    ((s["force_quality"] & FORCE_BITS[bit]) > 0).astype(np.int64),
                    FLAG_NAMES[bit], COLORS[bit])
    send_series(rec, "quality/hole", TIMELINE, t, s["hole"].astype(np.int64),
                "a hole (frames lost, or force read from a hole's edge)", COLORS["hole"])
    _log_scene(rec, r, rest, scale)
    if r.registration is not None:
        _shape(rec, r, r.registration, rest)
    _presses(rec, r)
    _holes(rec, r)


def _rest(markers: np.ndarray) -> np.ndarray:
    """Each marker's rest position: its median over the session (pressed only at times)."""
    with warnings.catch_warnings():          # a marker never seen has no rest position: NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmedian(markers, axis=0)


def _log_scene(rec: rr.RecordingStream, r: SyncResult, rest: np.ndarray, scale: float
               ) -> None:
    """Surface, markers, tip, shaft and the tip's path at VIEW_HZ."""
    s = r.session
    rows = np.arange(0, len(s["time_ns"]), max(1, ceil(r.rate_hz / VIEW_HZ)))
    t = s["time_ns"][rows]
    filled = (s["quality"][rows] & FILLED) > 0
    markers, tip = s["points"][rows, :-1], s["points"][rows, -1:]
    _surface(rec, t, markers, rest, scale)
    _points(rec, "scene/phantom", t, markers, filled[:, :-1], COLORS["phantom"], RADIUS_M)
    _points(rec, "scene/tip", t, tip, filled[:, -1:], COLORS["tip"], 2.5 * RADIUS_M)
    cluster = s["cluster"][rows]
    _points(rec, "scene/cluster", t, cluster, np.zeros(cluster.shape[:2], bool),
            COLORS["cluster"], RADIUS_M)
    with warnings.catch_warnings():          # a frame with no indenter marker: NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        top = np.nanmean(cluster, axis=1)
    strips = [np.stack([a, b]) for a, b in zip(tip[:, 0], top, strict=True)]
    rec.log("scene/shaft", rr.LineStrips3D.from_fields(colors=[COLORS["shaft"]],
                                                       radii=[0.0008]), static=True)
    rec.send_columns("scene/shaft", indexes=[time_column(TIMELINE, t)],
                     columns=rr.LineStrips3D.columns(strips=strips))
    path = s["tip"][rows]
    path = path[np.isfinite(path).all(axis=1)]
    if len(path) > 1:
        rec.log("scene/tip_path", rr.LineStrips3D([path], colors=[COLORS["path"]],
                                                  radii=[RADIUS_M / 5]), static=True)


def _shape(rec: rr.RecordingStream, r: SyncResult, registration: Registration,
           rest: np.ndarray) -> None:
    """The mould ``registration`` placed in the lab, and each marker's residual off it."""
    shape = PhantomLayout.from_json(r.phantom).shape
    if shape is None:
        raise ValueError("a registered phantom without its shape")
    log_mould(rec, "scene/shape", shape.vertices, shape.faces,
              np.linalg.inv(registration.to_shape))
    res = registration.residual
    ok = np.isfinite(rest).all(axis=1) & np.isfinite(res)
    names = r.point_names[:-1]
    rec.log("scene/residual", rr.Points3D(
        rest[ok], radii=RADIUS_M * 1.2, colors=colormap(np.abs(res[ok]) / RESIDUAL_SCALE_M),
        labels=[f"{names[k]} {res[k] * 1e3:+.2f} mm" for k in np.flatnonzero(ok)]),
        static=True)


def _surface(rec: rr.RecordingStream, t: np.ndarray, markers: np.ndarray, rest: np.ndarray,
             scale: float) -> None:
    """The surface through the phantom markers as a wire mesh (Delaunay triangles on their rest
    positions; wires, so the tip shows where it dents below them), each wire coloured by its
    markers' mean displacement; a marker missing in a frame sits at rest there."""
    ok = np.isfinite(rest).all(axis=1)
    if ok.sum() < 3:
        return
    centred = rest[ok] - rest[ok].mean(axis=0)
    plane = np.linalg.svd(centred, full_matrices=False)[2][:2]      # in-plane axes
    tri = Delaunay(centred @ plane.T).simplices
    edges = np.unique(np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [0, 2]]]),
                              axis=1), axis=0)                      # (E, 2)
    verts = np.where(np.isfinite(markers[:, ok]), markers[:, ok], rest[ok])
    moved = np.linalg.norm(verts - rest[ok], axis=2)                # (T, V)
    colors = colormap(moved[:, edges].mean(axis=2) / scale)         # (T, E, 3)
    rec.log("scene/surface", rr.LineStrips3D.from_fields(radii=[0.0007]), static=True)
    rec.send_columns("scene/surface", indexes=[time_column(TIMELINE, t)],
                     columns=rr.LineStrips3D.columns(strips=verts[:, edges].reshape(-1, 2, 3),
                                                     colors=colors.reshape(-1, 3))
                     .partition(np.full(len(t), len(edges))))


def _points(rec: rr.RecordingStream, path: str, t: np.ndarray, xyz: np.ndarray,
            filled: np.ndarray, color: tuple[int, ...], radius: float) -> None:
    """Points per frame (NaN ones left out), filled samples in the 'filled' colour."""
    ok = np.isfinite(xyz).all(axis=2)
    colors = np.where(filled[..., None], COLORS["filled"], color).astype(np.uint8)
    rec.log(path, rr.Points3D.from_fields(radii=[radius]), static=True)
    rec.send_columns(path, indexes=[time_column(TIMELINE, t)],
                     columns=rr.Points3D.columns(positions=xyz[ok], colors=colors[ok])
                     .partition(ok.sum(axis=1)))


def force_depth_png(s: dict) -> bytes:
    """Force over tip depth before and after alignment, as a PNG with axes and a legend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    depth = s["depth"] * 1e3
    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=110)
    for stage, key in (("before", "force_magnitude_unaligned"), ("after", "force_magnitude")):
        f = s[key]
        ok = np.flatnonzero(np.isfinite(depth) & np.isfinite(f) & (f > 0.02))
        ok = ok[:: max(1, ceil(len(ok) / SCATTER_MAX))]
        ax.scatter(depth[ok], f[ok], s=1.5, color=np.array(COLORS[stage]) / 255,
                   label=f"{stage} alignment", rasterized=True)
    ax.set_xlabel("tip depth below the rest surface [mm]")
    ax.set_ylabel("force magnitude [N]")
    ax.grid(alpha=0.3)
    ax.legend(markerscale=6, loc="upper left")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return buf.getvalue()


def _presses(rec: rr.RecordingStream, r: SyncResult) -> None:
    if not r.presses:
        return
    times = np.array([p.time_ns[p.press.onset] for p in r.presses], np.int64)
    text = [f"press {k}: location {p.press.location}, repeat {p.press.repeat}, peak "
            f"{p.force_magnitude[p.press.peak]:.2f} N" for k, p in enumerate(r.presses)]
    rec.send_columns("presses", indexes=[time_column(TIMELINE, times)],
                     columns=rr.TextLog.columns(text=text))


def _holes(rec: rr.RecordingStream, r: SyncResult) -> None:
    """A warning where each hole starts (mocap clock): what was lost and what it cost."""
    if not r.holes:
        return
    times = np.array([round(h["at_s"] * 1e9) for h in r.holes], np.int64)
    what = {"mocap": ("mocap frames", "frames"), "force": ("force samples", "samples")}
    text = [f"hole: {h['length_s']:.3f} s of {what[h['stream']][0]} lost ({h['lost']} "
            f"{what[h['stream']][1]}), " + ("bridged" if h["bridged"] else
                                            f"{count(len(h['presses_left_out']), 'press')} "
                                            "left out") for h in r.holes]
    rec.send_columns("presses", indexes=[time_column(TIMELINE, times)],
                     columns=rr.TextLog.columns(text=text, level=["WARN"] * len(text)))

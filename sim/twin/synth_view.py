"""The synth recording: one press of the twin, the truth beside what the instruments delivered.

What a person checks: does the phantom surface deform sensibly under the tip, do the measured
markers (noisy, with gaps) scatter around the true ones, does the force the logger recorded
(calibrated with the true bias, put on the mocap clock with the true clock) follow the true
force, and where are the static states. One timeline, ``mocap_time`` (the twin's mocap clock),
over the press from the hover point to the retract; +z is up and the camera frames the phantom.

Entities: ``phantom/surface`` (Mesh3D of the top surface, 50 Hz, coloured by depth below rest:
viridis, range in the view's name), ``truth/markers``, ``truth/cluster`` (Boxes3D: a green
wireframe cube around each true marker), ``measured/markers``, ``measured/cluster`` (Points3D:
orange balls inside the cubes, gaps left out), ``truth/tip`` (Points3D, red) and
``truth/shaft`` (LineStrips3D from the tip to the indenter's markers), ``truth/states``
(static Points3D: the tip at every 0.5 N state, magenta); ``phantom/places`` (static Points3D,
grey: every place the session presses, at rest); where the block has other silicones,
``phantom/inclusions`` (static Ellipsoids3D: each sphere, translucent, red when stiffer than the
block and blue when softer, labelled with its ratio), ``phantom/inclusion_outlines`` (static
LineStrips3D: each sphere's outline on the rest surface, seen from above through the pressed
surface) and ``phantom/layer`` (static Boxes3D: the top layer's slab as a wireframe, coloured
alike); ``force/truth`` (thick green line), ``force/measured`` (thin orange line) and
``force/states`` (magenta dots), N.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from scipy.spatial.transform import Rotation

from core.protocol import STEP_N
from core.recording import (
    colormap,
    declare_up,
    phantom_view,
    plot,
    recording,
    send_series,
    time_column,
)
from sim.twin.twin import Twin

APP_ID = "phantom-synth"
VIEW_HZ = 50.0
TIMELINE = "mocap_time"
COLORS: dict[str, tuple[int, ...]] = {
    "truth": (40, 180, 90), "truth_line": (40, 180, 90, 120),
    "measured": (245, 140, 30), "tip": (220, 40, 40),
    "shaft": (200, 200, 200), "states": (230, 60, 230), "places": (150, 150, 150),
    "stiffer": (230, 60, 40, 90), "softer": (50, 110, 230, 90)}
RADIUS_M = 0.0015        # the 3 mm marker spheres
BOX_M = 0.0025           # half side of the cube drawn around a true marker
OUTLINE_LIFT_M = 0.0005  # an inclusion's outline this far above the rest surface


def blueprint(twin: Twin, k: int, depth_mm: float) -> rrb.Blueprint:
    """The phantom in 3D on the left, framed from above; the force over time on the right."""
    spec = twin.phantom.spec
    size = spec.size
    rest = twin.paths[k].interpolate(np.zeros(1), "surface").reshape(-1, 3)
    centre = twin.lab(rest.mean(axis=0))
    up = twin.to_lab[:3, 2]
    regions = [f"inclusion {i.describe()}" for i in spec.inclusions] + (
        [] if spec.layer is None else [f"layer {spec.layer.describe()}"])
    return rrb.Blueprint(
        rrb.Horizontal(
            phantom_view(f"press {k}: {spec.markers.describe()} on {size[0] * 1e3:g} x "
                         f"{size[1] * 1e3:g} mm; depth 0 .. {depth_mm:.0f} mm; true markers in "
                         "green cubes, measured orange; places grey"
                         + "".join(f"; {r}" for r in regions)
                         + (" (red: stiffer, blue: softer)" if regions else ""),
                         ["+ /phantom/**", "+ /truth/**", "+ /measured/**"],
                         centre, max(size[:2]), up),
            plot(f"force magnitude [N]: truth green, logger orange, {STEP_N:g} N states",
                 "/force"),
            column_shares=[3, 2],
        ),
        collapse_panels=False,
    )


def write_twin_recording(twin: Twin, path: str | Path, press: int = 0) -> None:
    """Save the recording of press ``press`` of ``twin`` to ``path`` (atomically)."""
    frames = press_frames(twin, press)
    depth = surface_depth(twin, press, frames)
    with recording(APP_ID, path, blueprint(twin, press, float(depth.max()) * 1e3)) as rec:
        declare_up(rec)
        log_press(rec, twin, press, frames, depth)


def press_frames(twin: Twin, k: int) -> np.ndarray:
    """The mocap frames of press ``k`` from hover to retract, at most VIEW_HZ per second."""
    m, p = twin.mocap, twin.hand.presses[k]
    window = np.flatnonzero((m.time_s >= p.times[1]) & (m.time_s <= p.times[7]))
    return window[::max(1, int(round(twin.params.rate_hz / VIEW_HZ)))]


def surface_vertices(twin: Twin, k: int, frames: np.ndarray) -> np.ndarray:
    """(F, V, 3) the top surface at the frames, phantom frame (0 N before and after)."""
    force = np.where(twin.mocap.press[frames] == k, twin.mocap.force[frames], 0.0)
    return twin.paths[k].interpolate(force, "surface").reshape(len(frames), -1, 3)


def surface_depth(twin: Twin, k: int, frames: np.ndarray) -> np.ndarray:
    """(F, V) how far each surface vertex is pressed below its rest height (m)."""
    rest = twin.paths[k].interpolate(np.zeros(1), "surface").reshape(-1, 3)
    return np.maximum(rest[:, 2] - surface_vertices(twin, k, frames)[..., 2], 0.0)


def log_press(rec: rr.RecordingStream, twin: Twin, k: int, frames: np.ndarray,
              depth: np.ndarray) -> None:
    """Log press ``k``: surface, true and measured markers, tip, force and static states."""
    m, n = twin.mocap, twin.phantom.n_markers
    ns = _ns(m.time_s[frames])
    _log_surface(rec, twin, k, frames, ns, depth)
    _log_boxes(rec, "truth/markers", m.points[frames, :n], ns)
    _log_boxes(rec, "truth/cluster", m.cluster[frames], ns)
    _log_points(rec, "measured/markers", m.measured[frames, :n], ns, COLORS["measured"])
    _log_points(rec, "measured/cluster", m.measured[frames, n:], ns, COLORS["measured"])
    _log_points(rec, "truth/tip", m.points[frames, n:], ns, COLORS["tip"], radius=0.002)
    shafts = np.stack([m.points[frames, n], m.cluster[frames].mean(axis=1)], axis=1)
    rec.log("truth/shaft", rr.LineStrips3D.from_fields(colors=[COLORS["shaft"]],
                                                       radii=[0.0008]), static=True)
    rec.send_columns("truth/shaft", indexes=[time_column(TIMELINE, ns)],
                     columns=rr.LineStrips3D.columns(strips=list(shafts)))
    mine = twin.states.press == k
    rec.log("truth/states", rr.Points3D(twin.states.points[mine, n],
                                        colors=[COLORS["states"]], radii=[0.0012]), static=True)
    _log_force(rec, twin, frames, mine)
    rec.log("phantom/places", rr.Points3D(twin.contacts, colors=[COLORS["places"]],
                                          radii=[0.001]), static=True)
    log_regions(rec, twin)


def log_regions(rec: rr.RecordingStream, twin: Twin) -> None:
    """The block's inclusions (spheres and their outlines on the rest surface) and its top
    layer (a slab), in the lab, coloured by whether they are stiffer or softer."""
    spec = twin.phantom.spec
    inc = spec.inclusions
    if inc:
        colors = [_region_color(i.ratio) for i in inc]
        rec.log("phantom/inclusions", rr.Ellipsoids3D(
            centers=twin.lab(np.array([i.centre(spec.size) for i in inc])),
            half_sizes=[[i.radius] * 3 for i in inc], colors=colors, fill_mode="solid",
            labels=[f"{i.ratio:g}x" for i in inc], show_labels=True), static=True)
        turn = np.linspace(0.0, 2 * np.pi, 65)
        rings = [np.stack([i.centre(spec.size)[0] + i.radius * np.cos(turn),
                           i.centre(spec.size)[1] + i.radius * np.sin(turn),
                           np.full(turn.shape, spec.size[2] + OUTLINE_LIFT_M)], axis=1)
                 for i in inc]
        rec.log("phantom/inclusion_outlines", rr.LineStrips3D(
            [twin.lab(r) for r in rings], colors=[c[:3] for c in colors], radii=[0.0004]),
            static=True)
    if spec.layer is not None:
        t = spec.layer.thickness
        turn = Rotation.from_matrix(twin.to_lab[:3, :3]).as_quat()      # x, y, z, w
        rec.log("phantom/layer", rr.Boxes3D(
            centers=twin.lab(np.array([[0.0, 0.0, spec.size[2] - t / 2]])),
            half_sizes=[[spec.size[0] / 2, spec.size[1] / 2, t / 2]],
            quaternions=[rr.Quaternion(xyzw=turn)], colors=[_region_color(spec.layer.ratio)],
            fill_mode="majorwireframe", radii=[0.0004]), static=True)


def _region_color(ratio: float) -> tuple[int, ...]:
    return COLORS["stiffer"] if ratio >= 1.0 else COLORS["softer"]


def _ns(time_s: np.ndarray) -> np.ndarray:
    return np.round(np.asarray(time_s) * 1e9).astype(np.int64)


def _log_points(rec: rr.RecordingStream, path: str, xyz: np.ndarray, ns: np.ndarray,
                color: tuple[int, ...], radius: float = RADIUS_M) -> None:
    """Points per frame (T, N, 3); NaN points are left out of their frame."""
    rec.log(path, rr.Points3D.from_fields(colors=[color], radii=[radius]), static=True)
    ok = np.isfinite(xyz).all(axis=2)
    rec.send_columns(path, indexes=[time_column(TIMELINE, ns)],
                     columns=rr.Points3D.columns(positions=xyz[ok]).partition(ok.sum(axis=1)))


def _log_boxes(rec: rr.RecordingStream, path: str, xyz: np.ndarray, ns: np.ndarray) -> None:
    """A wireframe cube around each true point per frame (T, N, 3), so the measured ball
    inside it shows too."""
    rec.log(path, rr.Boxes3D.from_fields(half_sizes=[[BOX_M] * 3], colors=[COLORS["truth"]],
                                         fill_mode="majorwireframe", radii=[0.0003]),
            static=True)
    rec.send_columns(path, indexes=[time_column(TIMELINE, ns)],
                     columns=rr.Boxes3D.columns(centers=xyz.reshape(-1, 3))
                     .partition(np.full(len(ns), xyz.shape[1])))


def _log_surface(rec: rr.RecordingStream, twin: Twin, k: int, frames: np.ndarray,
                 ns: np.ndarray, depth: np.ndarray) -> None:
    """The top surface as a triangle mesh at each frame, coloured by depth below rest."""
    nx, ny = twin.paths[k].surface.shape[1:3]
    vertices = twin.lab(surface_vertices(twin, k, frames))
    grid = np.arange(nx * ny).reshape(nx, ny)
    a, b, c, d = grid[:-1, :-1], grid[1:, :-1], grid[1:, 1:], grid[:-1, 1:]
    triangles = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                                np.stack([a, c, d], -1).reshape(-1, 3)])
    colors = colormap(depth / max(float(depth.max()), 1e-9))
    rec.log("phantom/surface", rr.Mesh3D.from_fields(triangle_indices=triangles), static=True)
    rec.send_columns("phantom/surface", indexes=[time_column(TIMELINE, ns)],
                     columns=rr.Mesh3D.columns(vertex_positions=vertices.reshape(-1, 3),
                                               vertex_colors=colors.reshape(-1, 3))
                     .partition(np.full(len(frames), nx * ny)))


def _log_force(rec: rr.RecordingStream, twin: Twin, frames: np.ndarray,
               mine: np.ndarray) -> None:
    """True force at full rate; the logged force (true bias, matrix and clock) beside it;
    the static states as dots."""
    m, log, sensor = twin.mocap, twin.log, twin.sensor
    window = np.arange(frames[0], frames[-1] + 1)
    send_series(rec, "force/truth", TIMELINE, _ns(m.time_s[window]), m.force[window],
                "true force", COLORS["truth_line"], width=4.0)
    t0, t1 = m.time_s[window[0]], m.time_s[window[-1]]
    rows = np.flatnonzero((log.mocap_time_s >= t0) & (log.mocap_time_s <= t1))
    measured = np.linalg.norm(sensor.wrench(log.volts[rows], log.time_s[rows])[:, :3], axis=1)
    send_series(rec, "force/measured", TIMELINE, _ns(log.mocap_time_s[rows]), measured,
                "logged force", COLORS["measured"], width=1.0)
    st = twin.states
    rec.log("force/states", rr.SeriesPoints(names=[f"{STEP_N:g} N states"],
                                            colors=[COLORS["states"]], markers=["circle"],
                                            marker_sizes=[4.0]),
            static=True)
    rec.send_columns("force/states", indexes=[time_column(TIMELINE, _ns(st.time_s[mine]))],
                     columns=rr.Scalars.columns(scalars=st.force[mine]))

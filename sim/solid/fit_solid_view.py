"""The fit-solid recording: the interior, the fitted solid beside the measured markers, and the
residual per marker.

What a person checks after fit-solid: is the lump where the volume says, does the fitted
solid's surface dent where and as far as the phantom did, and which markers it misses. One
timeline, ``force_step`` (the levels of each shown press in order):

- ``interior/label_<k>``: Boxes3D, the elements mostly of label k (k >= 1), translucent;
- ``fit/seq_<s>/solid``: Mesh3D, the fitted solid's top face under press s, coloured by how
  far it moved (viridis, 0 .. the deepest shown press's largest, square root scale, the
  range in the view's name), a little translucent so the interior shows through;
- ``fit/seq_<s>/measured``: Points3D, the measured markers and tip (orange);
- ``fit/seq_<s>/model``: Points3D, the solid's markers and tip (blue), joined to the measured
  ones by red ``fit/seq_<s>/error`` segments;
- ``residual/per_marker``: BarChart, each marker's mean distance (mm), in the file's order.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from core.recording import colormap, declare_up, phantom_view, recording
from sim.solid.elasticity import Solver
from sim.solid.measured_presses import MeasuredPress, MeasuredSet
from sim.solid.solid_fit import SolidFit, SolidMaterial, residuals
from sim.solid.solid_model import PlaceResponse, SolidModel, point_scale, tip_scale

APP_ID = "phantom-fit-solid"
MEASURED, MODEL, ERROR = (255, 127, 14), (31, 119, 180), (214, 39, 40)
SURFACE_ALPHA = 190
LABEL_COLOURS = ((214, 39, 40, 150), (44, 160, 44, 150), (148, 103, 189, 150), (140, 86, 75, 150))


def write_solid_recording(path: str | Path, model: SolidModel, solver: Solver,
                          data: MeasuredSet, responses: list[PlaceResponse], fit: SolidFit,
                          shares: np.ndarray, count: int = 4) -> None:
    """Save the recording of ``count`` presses under the fitted material: spread over the
    file, the first of them the press nearest the interior's inclusions (where a lump is)."""
    shown = _shown(model, data, shares, count)
    length, width = data.footprint
    size = max(length, width)
    centre = np.array([length / 2, width / 2, -size * 0.05])
    rest, triangles = model.top_face()
    fields = {i: _surface(model, solver, data.presses[i], responses[i], fit.material, rest)
              for i in shown}
    largest = max(float(np.linalg.norm(f, axis=-1).max()) for f in fields.values())
    views = [phantom_view(f"press {data.presses[i].sequence}: fitted solid 0 .. "
                          f"{largest * 1e3:.1f} mm (sqrt), measured orange, solid blue, "
                          "interior red",
                          [f"+ /fit/seq_{data.presses[i].sequence:04d}/**", "+ /interior/**"],
                          centre, size) for i in shown]
    bp = rrb.Blueprint(rrb.Horizontal(
        rrb.Grid(*views),
        rrb.BarChartView(name=f"mean distance per marker [mm] (all {fit.marker_mm:.3f}; "
                              f"still surface {fit.still_mm:.3f})", origin="/residual"),
        column_shares=[3, 1]), collapse_panels=False)
    per_press = residuals(data, responses, fit.material)
    with recording(APP_ID, path, bp) as rec:
        if rec is None:
            return
        declare_up(rec)
        _log_interior(rec, model, shares)
        for i in shown:
            _log_press(rec, data.presses[i], fields[i], per_press[i], (rest, triangles),
                       largest)
        rec.log("residual/per_marker", rr.BarChart(fit.per_marker_mm, color=MODEL), static=True)


def _shown(model: SolidModel, data: MeasuredSet, shares: np.ndarray, count: int) -> list[int]:
    """Which presses to show: the one nearest the elements of labels >= 1, then a spread."""
    spread = list(range(0, len(data.presses), max(1, len(data.presses) // count)))
    inside = shares[:, 1:].sum(axis=1) > 0.5
    if not inside.any():
        return spread[:count]
    centre = model.elasticity.element_centres()[inside].mean(axis=0)
    places = np.array([p.rest[-1, :2] for p in data.presses])
    nearest = int(np.argmin(np.linalg.norm(places - centre[:2], axis=1)))
    return [nearest, *[i for i in spread if i != nearest]][:count]


def _log_interior(rec: rr.RecordingStream, model: SolidModel, shares: np.ndarray) -> None:
    """The elements mostly of each label but the block's, as translucent boxes."""
    mesh = model.elasticity.mesh
    corners = mesh.p[:, mesh.t]
    lo, hi = corners.min(axis=1).T, corners.max(axis=1).T
    for k in range(1, shares.shape[1]):
        mostly = shares[:, k] > 0.5
        if mostly.any():
            colour = LABEL_COLOURS[(k - 1) % len(LABEL_COLOURS)]
            rec.log(f"interior/label_{k}", rr.Boxes3D(
                centers=(lo[mostly] + hi[mostly]) / 2, half_sizes=(hi[mostly] - lo[mostly]) / 2,
                colors=[colour], fill_mode="solid"), static=True)


def _surface(model: SolidModel, solver: Solver, press: MeasuredPress, resp: PlaceResponse,
             material: SolidMaterial, rest: np.ndarray) -> np.ndarray:
    """(T, n, 3) the top face's displacement at each level of ``press``."""
    unit = model.surface(solver, resp.place, material.contact_radius)       # (3, n, 3)
    loads = press.loads(resp.tip)
    fields = np.einsum("tk,knc->tnc", loads, unit) / material.modulus
    s_tip = tip_scale(loads @ resp.tip / material.modulus, material.stiffening)
    return fields * point_scale(s_tip, resp.place, rest, material.reach)[..., None]


def _log_press(rec: rr.RecordingStream, press: MeasuredPress, fields: np.ndarray,
               residual: np.ndarray, face: tuple[np.ndarray, np.ndarray], largest: float
               ) -> None:
    """One press: the solid's top face at each level, the measured and modelled points."""
    rest, triangles = face
    root = f"fit/seq_{press.sequence:04d}"
    rec.log(f"{root}/solid", rr.Mesh3D.from_fields(triangle_indices=triangles), static=True)
    for name, color in (("measured", MEASURED), ("model", MODEL)):
        rec.log(f"{root}/{name}", rr.Points3D.from_fields(radii=[0.0012], colors=[color]),
                static=True)
    rec.log(f"{root}/error", rr.LineStrips3D.from_fields(radii=[0.0004], colors=[ERROR]),
            static=True)
    for t in range(len(fields)):
        rec.set_time("force_step", sequence=t + 1)
        moved = np.sqrt(np.linalg.norm(fields[t], axis=-1) / max(largest, 1e-12))
        colours = np.c_[colormap(moved), np.full(len(rest), SURFACE_ALPHA)].astype(np.uint8)
        rec.log(f"{root}/solid", rr.Mesh3D.from_fields(vertex_positions=rest + fields[t],
                                                       vertex_colors=colours))
        measured = press.states[t]
        model_pts = measured + residual[t]
        keep = np.isfinite(measured).all(axis=1)
        rec.log(f"{root}/measured", rr.Points3D.from_fields(positions=measured[keep]))
        rec.log(f"{root}/model", rr.Points3D.from_fields(positions=model_pts[keep]))
        rec.log(f"{root}/error", rr.LineStrips3D.from_fields(
            strips=list(np.stack([measured[keep], model_pts[keep]], axis=1))))

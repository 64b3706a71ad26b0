"""The fit-msm recording: the fitted MSM beside the measured markers, and the distance per press.

What a person checks after fit-msm: does the fitted surface dent where and as far as the
phantom did, and is it closer to every press than a still surface. One timeline,
``force_step`` (the measured levels of each press in order). Per shown sequence ``s``:

- ``fit/seq_<s>/msm``: Mesh3D of the fitted MSM, coloured by displacement (viridis, square
  root scale, the range in the view's name);
- ``fit/seq_<s>/measured``: Points3D, the measured points (orange);
- ``fit/seq_<s>/model``: Points3D, the MSM at those points (blue), joined to the measured ones
  by red ``fit/seq_<s>/error`` segments;
- ``distance/*``: bar charts (static), one bar per press in the fit's order: the mean distance
  of the fitted MSM, of the start constants and of a still surface, in mm, side by side;
- with a stiffness map (``fit-msm --map``), ``map/regions``: a 2D view of the footprint (x
  right, y down as rerun draws 2D; mm), one box per region coloured by its factor (viridis
  over the map's range, written in the view's name) and labelled ``factor +- sd [n]``, ``n``
  the presses informing it (their tips within 5 mm; ``held`` where none does),
  ``map/stiffest``: the stiffest fitted region outlined red, ``map/peak``: the peak among it
  and its neighbours (a red point, where the map puts a lump), and ``map/presses``: the
  presses' tips at rest. The map has a column of its own, beside the presses.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from core.recording import colormap, declare_up, phantom_view, recording
from sim.msm.msm import MSM, MSMParams
from sim.msm.msm_fit import FitResult, at_points, grid_states
from sim.msm.msm_map_fit import MapResult, tip_xy
from sim.msm.msm_measured import MeasuredSequence
from sim.msm.msm_regions import region_centres

APP_ID = "phantom-fit-msm"
MEASURED, MODEL, ERROR = (255, 127, 14), (31, 119, 180), (214, 39, 40)
SERIES = (("fitted_m", "fitted MSM", (31, 119, 180)), ("start_m", "start constants",
                                                        (148, 103, 189)),
          ("still_m", "still surface", (127, 127, 127)))


def write_fit_recording(path: str | Path, params: MSMParams, result: FitResult,
                        sequences: list[MeasuredSequence], found: MapResult | None = None,
                        count: int = 4) -> None:
    """Save the recording of ``count`` sequences under the fitted constants (and the map
    ``found`` where one was fitted)."""
    fitted = MSMParams(**{**params.as_dict(), "k_between": result.k_between,
                          "k_fixed": result.k_fixed})
    model = MSM(fitted)
    shown = sequences[:: max(1, len(sequences) // max(count, 1))][:count]
    states = [grid_states(fitted, s) for s in shown]
    largest = max((np.linalg.norm(x - model.rest, axis=-1).max() for x in states), default=0.0)
    length, width = fitted.footprint
    size = max(length, width)
    views = [phantom_view(f"press {s.sequence}: fitted MSM 0 .. {largest * 1e3:.1f} mm (sqrt), "
                          "measured orange, model blue", [f"+ /fit/seq_{s.sequence:04d}/**"],
                          np.array([length / 2, width / 2, -size * 0.05]), size)
             for s in shown]
    bars = rrb.Vertical(*(rrb.BarChartView(name=f"{name}: mean distance per press [mm]",
                                           origin=f"/distance/{key[:-2]}")
                          for key, name, _ in SERIES))
    columns: list = [rrb.Grid(*views), bars]
    if found is not None:                     # the map first, as large as the presses' grid
        factors = np.asarray(found.factors)
        columns.insert(0, rrb.Spatial2DView(
            name=f"stiffness map {found.shape[0]}x{found.shape[1]}: factor {factors.min():.2f}"
                 f" .. {factors.max():.2f} (viridis), stiffest outlined red, [presses informing "
                 "each], the peak red; press tips orange [mm, y down]",
            origin="/map"))
    bp = rrb.Blueprint(rrb.Horizontal(*columns, column_shares=[3] * (len(columns) - 1) + [2]),
                       collapse_panels=False)
    with recording(APP_ID, path, bp) as rec:
        declare_up(rec)
        for seq, grid in zip(shown, states, strict=True):
            _log_press(rec, model, seq, grid, at_points(fitted, seq, grid), largest)
        _log_distances(rec, result)
        if found is not None:
            _log_map(rec, found, params.footprint, sequences)


def _log_press(rec: rr.RecordingStream, model: MSM, seq: MeasuredSequence, grid: np.ndarray,
               predicted: np.ndarray, largest: float) -> None:
    """One press: the fitted surface, the measured and modelled points, their gaps."""
    root, t = f"fit/seq_{seq.sequence:04d}", len(grid)
    times = [rr.TimeColumn("force_step", sequence=np.arange(1, t + 1))]
    colors = colormap(np.sqrt(np.linalg.norm(grid - model.rest, axis=-1) / max(largest, 1e-12)))
    rec.log(f"{root}/msm", rr.Mesh3D.from_fields(triangle_indices=model.triangles()),
            static=True)
    rec.send_columns(f"{root}/msm", indexes=times, columns=rr.Mesh3D.columns(
        vertex_positions=grid.reshape(-1, 3), vertex_colors=colors.reshape(-1, 3))
        .partition(np.full(t, model.N)))
    measured = seq.points
    keep = np.isfinite(measured).all(axis=-1) & np.isfinite(predicted).all(axis=-1)  # (T, P)
    for name, pts, color in (("measured", measured, MEASURED), ("model", predicted, MODEL)):
        rec.log(f"{root}/{name}", rr.Points3D.from_fields(radii=[0.0012], colors=[color]),
                static=True)
        rec.send_columns(f"{root}/{name}", indexes=times, columns=rr.Points3D.columns(
            positions=pts[keep]).partition(keep.sum(axis=1)))
    segments = np.stack([measured[keep], predicted[keep]], axis=1)          # (K, 2, 3)
    rec.log(f"{root}/error", rr.LineStrips3D.from_fields(radii=[0.0004], colors=[ERROR]),
            static=True)
    rec.send_columns(f"{root}/error", indexes=times, columns=rr.LineStrips3D.columns(
        strips=list(segments)).partition(keep.sum(axis=1)))


def _log_distances(rec: rr.RecordingStream, result: FitResult) -> None:
    """The mean distance per press of the fitted MSM, the start constants and stillness."""
    for key, _, color in SERIES:
        values = [row[key] * 1e3 for row in result.per_sequence]
        rec.log(f"distance/{key[:-2]}", rr.BarChart(values, color=color), static=True)


def _log_map(rec: rr.RecordingStream, found: MapResult, footprint: tuple[float, float],
             sequences: list[MeasuredSequence]) -> None:
    """The map over the footprint (mm): a box per region, the presses and what they inform."""
    rows, cols = found.shape
    factors = np.asarray(found.factors).ravel()
    span = max(float(factors.max() - factors.min()), 1e-9)
    centres = region_centres(footprint, found.shape).reshape(-1, 2) * 1e3
    half = np.array([footprint[0] / cols, footprint[1] / rows]) * 1e3 / 2
    counts = [len(presses) for row in found.informed_by for presses in row]
    labels = [(f"{f:.2f} +- {sd:.2g} [{n}]" if sd is not None else f"{f:.2f} (held)")
              for f, sd, n in zip(factors, [v for row in found.sd for v in row], counts,
                                  strict=True)]
    rec.log("map/regions", rr.Boxes2D(centers=centres, half_sizes=np.tile(half * 0.97,
                                                                            (len(centres), 1)),
                                      colors=colormap((factors - factors.min()) / span),
                                      labels=labels, show_labels=True), static=True)
    if found.stiffest is not None:
        top = found.stiffest
        rec.log("map/stiffest", rr.Boxes2D(centers=[top["centre_mm"]], half_sizes=[half * 0.97],
                                           radii=[0.8], colors=[ERROR], draw_order=20.0),
                static=True)
        rec.log("map/peak", rr.Points2D([top["peak_mm"]], radii=[2.0], colors=[ERROR],
                                        labels=["peak"], draw_order=40.0), static=True)
    tips = [tip_xy(s) * 1e3 for s in sequences]                   # repeats share a place
    rec.log("map/presses", rr.Points2D(tips, radii=[1.2], colors=[MEASURED], draw_order=30.0),
            static=True)

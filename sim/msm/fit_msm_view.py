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
  of the fitted MSM, of the start constants and of a still surface, in mm, side by side.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from core.recording import colormap, declare_up, phantom_view, recording
from sim.msm.msm import MSM, MSMParams
from sim.msm.msm_fit import FitResult, at_points, grid_states
from sim.msm.msm_measured import MeasuredSequence

APP_ID = "phantom-fit-msm"
MEASURED, MODEL, ERROR = (255, 127, 14), (31, 119, 180), (214, 39, 40)
SERIES = (("fitted_m", "fitted MSM", (31, 119, 180)), ("start_m", "start constants",
                                                        (148, 103, 189)),
          ("still_m", "still surface", (127, 127, 127)))


def write_fit_recording(path: str | Path, params: MSMParams, result: FitResult,
                        sequences: list[MeasuredSequence], count: int = 4) -> None:
    """Save the recording of ``count`` sequences under the fitted constants."""
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
    bp = rrb.Blueprint(rrb.Horizontal(rrb.Grid(*views), bars, column_shares=[3, 2]),
                       collapse_panels=False)
    with recording(APP_ID, path, bp) as rec:
        declare_up(rec)
        for seq, grid in zip(shown, states, strict=True):
            _log_press(rec, model, seq, grid, at_points(fitted, seq, grid), largest)
        _log_distances(rec, result)


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

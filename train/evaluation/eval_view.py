"""The evaluation recording: predicted beside true surfaces, coloured by error, and forces,
next to the Table-2 scores of every run beside the no-learning references.

Timeline ``example`` (test examples of the first run, named in the 3-D view's title).
Entities: ``surface/true`` the true deformed points (grey), ``surface/predicted`` the
prediction coloured by each point's error (blue 0 mm .. red ``ERROR_MM`` and above),
``surface/input`` the undeformed input (faint), ``surface/tip`` the tip at start and end;
``force/true`` and ``force/predicted`` the change of force (N); ``table`` (static) the
Markdown of ``metrics.md``, so a model that does not beat the references is seen beside it.
Where the run keeps intervals, ``interval/points``: the predicted points coloured by their
error over their 90 % radius (green well inside, yellow at the radius, red at twice it and
beyond), ``interval/tip`` the tip, in a view of their own.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from core.recording import colormap, declare_up, phantom_view, recording
from train.data import Batch
from train.evaluation.lump import LUMP_REACH_M, Lump
from train.model.si_units import BatchPrediction

APP_ID = "phantom-eval"
ERROR_MM = 2.0


def blueprint(centre: np.ndarray, size: float, shown: str, intervals: bool = False,
              footprint: str | None = None) -> rrb.Blueprint:
    """The predicted beside the true surface, framed from above (and, with ``intervals``,
    the points coloured by error over radius); the force change; the scores beside the
    references; with ``footprint`` (its view's name), the error over the footprint."""
    surface = phantom_view(f"{shown}: predicted (colour: error 0..{ERROR_MM:g} mm, blue..red) "
                           "beside true (grey)", ["+ /surface/**"], centre, size,
                           origin="/surface")
    views = [surface, phantom_view(f"{shown}: error / 90 % radius (green inside, yellow at "
                                   "the radius, red at twice it)", ["+ /interval/**"], centre,
                                   size, origin="/interval")] if intervals else [surface]
    return rrb.Blueprint(rrb.Horizontal(
        rrb.Vertical(*views),
        rrb.Vertical(
            rrb.TimeSeriesView(name="change of force [N]: true vs predicted", origin="/force"),
            rrb.TextDocumentView(name="scores beside the no-learning references",
                                 origin="/table"),
            *([rrb.Spatial2DView(name=footprint, origin="/footprint")] if footprint else []),
        ),
        column_shares=[3, 2],
    ), collapse_panels=True)


def error_colors(err_mm: np.ndarray) -> np.ndarray:
    """Blue (0) to red (``ERROR_MM`` and above), (M, 3) uint8."""
    t = np.clip(err_mm / ERROR_MM, 0, 1)[:, None]
    return (np.array([40, 110, 230]) * (1 - t) + np.array([230, 40, 40]) * t).astype(np.uint8)


def ratio_colors(ratio: np.ndarray) -> np.ndarray:
    """Error over radius as colour (M, 3) uint8: green (0) to yellow (1, at the radius) to
    red (2, twice outside it, and beyond)."""
    t = np.clip(ratio, 0, 2)[:, None]
    green, yellow, red = (np.array(c, float) for c in ((40, 170, 70), (240, 210, 40),
                                                        (220, 30, 30)))
    inside = green * (1 - np.minimum(t, 1)) + yellow * np.minimum(t, 1)
    return np.where(t <= 1, inside, yellow * (2 - t) + red * (t - 1)).astype(np.uint8)


def write_eval_recording(path: str | Path, shown: list[tuple[Batch, BatchPrediction]], name: str,
                         table: str, ratios: list[np.ndarray] | None = None,
                         footprint: tuple | None = None) -> None:
    """Log the examples in ``shown`` (the test batches of the run ``name``), with
    ``ratios`` (per batch (B, N): each point's error over its 90 % radius) where the run
    keeps intervals, ``table`` (the Markdown scores of every run beside the references),
    and ``footprint`` (the test places (K, 2) m, their mean L_d (K,) m, the lump or None:
    :func:`train.evaluation.scoring.footprint_errors`)."""
    first = shown[0][0].target[0][shown[0][0].mask[0]].cpu().numpy() if shown else np.zeros((1, 3))
    size = max(float(np.ptp(first[:, :2], axis=0).max()), 0.02)
    view = blueprint(first.mean(axis=0), size, name, ratios is not None,
                     None if footprint is None else
                     f"mean L_d per test place: 0 .. {footprint[1].max() * 1e3:.2f} mm "
                     "(viridis, size); the lump and its reach [mm]")
    with recording(APP_ID, path, view) as rec:
        declare_up(rec)
        rec.log("table", rr.TextDocument(table, media_type=rr.MediaType.MARKDOWN), static=True)
        if footprint is not None:
            _footprint(rec, *footprint)
        rec.log("force/true", rr.SeriesPoints(names=["true dF [N]"], colors=[(90, 90, 90)],
                                              marker_sizes=[4]), static=True)
        rec.log("force/predicted", rr.SeriesPoints(names=["predicted dF [N]"],
                                                   colors=[(230, 90, 40)], markers=["cross"],
                                                   marker_sizes=[4]), static=True)
        i = 0
        for k, (b, p) in enumerate(shown):
            for j in range(len(b.dforce)):
                rec.set_time("example", sequence=i)
                _example(rec, b, p, j)
                if ratios is not None:
                    _interval(rec, b, p, j, ratios[k][j])
                i += 1


def _interval(rec: rr.RecordingStream, b: Batch, p: BatchPrediction, j: int, ratio: np.ndarray
              ) -> None:
    """One example's predicted points coloured by error over radius, and its tip."""
    m = b.mask[j].cpu().numpy()
    rec.log("interval/points", rr.Points3D(p.deformed[j].cpu().numpy()[m],
                                           colors=ratio_colors(ratio[m]), radii=[0.0009]))
    rec.log("interval/tip", rr.Points3D(b.cond[j].cpu().numpy().reshape(2, 3),
                                        colors=[(250, 200, 40), (220, 40, 40)], radii=[0.0015]))


def _example(rec: rr.RecordingStream, b: Batch, p: BatchPrediction, j: int) -> None:
    m = b.mask[j].cpu().numpy()
    true, pred = b.target[j].cpu().numpy()[m], p.deformed[j].cpu().numpy()[m]
    err = np.linalg.norm(pred - true, axis=1) * 1e3
    rec.log("surface/true", rr.Points3D(true, colors=[(170, 170, 170)], radii=[0.0006]))
    rec.log("surface/predicted", rr.Points3D(pred, colors=error_colors(err), radii=[0.0009]))
    rec.log("surface/input", rr.Points3D(b.points[j].cpu().numpy()[m], colors=[(70, 70, 90)],
                                         radii=[0.0003]))
    rec.log("surface/tip", rr.Points3D(b.cond[j].cpu().numpy().reshape(2, 3),
                                       colors=[(250, 200, 40), (220, 40, 40)], radii=[0.0015]))
    rec.log("force/true", rr.Scalars(float(b.dforce[j])))
    rec.log("force/predicted", rr.Scalars(float(p.dforce[j])))


def _footprint(rec: rr.RecordingStream, xy: np.ndarray, ld: np.ndarray, lump: Lump | None
               ) -> None:
    """Each test place on the footprint (mm), coloured and sized by its mean L_d; the lump's
    radius and its reach (radius + :data:`~train.evaluation.lump.LUMP_REACH_M`) as circles."""
    top = max(float(ld.max()), 1e-12)
    rec.log("footprint/places", rr.Points2D(xy * 1e3, radii=1.0 + 3.0 * ld / top,
                                            colors=colormap(ld / top),
                                            labels=[f"{v * 1e3:.2f}" for v in ld]), static=True)
    if lump is not None:
        angle = np.linspace(0, 2 * np.pi, 65)
        rings = [np.c_[lump.x + r * np.cos(angle), lump.y + r * np.sin(angle)] * 1e3
                 for r in (lump.radius, lump.radius + LUMP_REACH_M)]
        rec.log("footprint/lump", rr.LineStrips2D(rings, colors=[(220, 40, 40), (250, 160, 60)],
                                                  radii=[0.4]), static=True)

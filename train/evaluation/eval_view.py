"""The evaluation recording: predicted beside true surfaces, coloured by error, and forces,
next to the Table-2 scores of every run beside the no-learning references.

Timeline ``example`` (test examples of the first run, named in the 3-D view's title).
Entities: ``surface/true`` the true deformed points (grey), ``surface/predicted`` the
prediction coloured by each point's error (blue 0 mm .. red ``ERROR_MM`` and above),
``surface/input`` the undeformed input (faint), ``surface/tip`` the tip at start and end;
``force/true`` and ``force/predicted`` the change of force (N); ``table`` (static) the
Markdown of ``metrics.md``, so a model that does not beat the references is seen beside it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from core.recording import declare_up, phantom_view, recording
from train.data import Batch
from train.model.si_units import Prediction

APP_ID = "phantom-eval"
ERROR_MM = 2.0


def blueprint(centre: np.ndarray, size: float, shown: str) -> rrb.Blueprint:
    """The predicted beside the true surface, framed from above; the force change; the
    scores beside the references."""
    return rrb.Blueprint(rrb.Horizontal(
        phantom_view(f"{shown}: predicted (colour: error 0..{ERROR_MM:g} mm, blue..red) "
                     "beside true (grey)", ["+ /surface/**"], centre, size, origin="/surface"),
        rrb.Vertical(
            rrb.TimeSeriesView(name="change of force [N]: true vs predicted", origin="/force"),
            rrb.TextDocumentView(name="scores beside the no-learning references",
                                 origin="/table"),
        ),
        column_shares=[3, 2],
    ), collapse_panels=True)


def error_colors(err_mm: np.ndarray) -> np.ndarray:
    """Blue (0) to red (``ERROR_MM`` and above), (M, 3) uint8."""
    t = np.clip(err_mm / ERROR_MM, 0, 1)[:, None]
    return (np.array([40, 110, 230]) * (1 - t) + np.array([230, 40, 40]) * t).astype(np.uint8)


def write_eval_recording(path: str | Path, shown: list[tuple[Batch, Prediction]], name: str,
                         table: str) -> None:
    """Log the examples in ``shown`` (the test batches of the run ``name``) and ``table``
    (the Markdown scores of every run beside the references)."""
    first = shown[0][0].target[0][shown[0][0].mask[0]].cpu().numpy() if shown else np.zeros((1, 3))
    size = max(float(np.ptp(first[:, :2], axis=0).max()), 0.02)
    with recording(APP_ID, path, blueprint(first.mean(axis=0), size, name)) as rec:
        declare_up(rec)
        rec.log("table", rr.TextDocument(table, media_type=rr.MediaType.MARKDOWN), static=True)
        rec.log("force/true", rr.SeriesPoints(names=["true dF [N]"], colors=[(90, 90, 90)],
                                              marker_sizes=[4]), static=True)
        rec.log("force/predicted", rr.SeriesPoints(names=["predicted dF [N]"],
                                                   colors=[(230, 90, 40)], markers=["cross"],
                                                   marker_sizes=[4]), static=True)
        i = 0
        for b, p in shown:
            for j in range(len(b.dforce)):
                rec.set_time("example", sequence=i)
                _example(rec, b, p, j)
                i += 1


def _example(rec: rr.RecordingStream, b: Batch, p: Prediction, j: int) -> None:
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

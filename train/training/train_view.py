"""The training recording: did it learn, and is validation following?

Timeline ``epoch``. Entities: ``loss/train``, ``loss/val`` (the paper's loss, 88 L_d[m] +
MSE[N^2]); ``val/ld_mm`` (validation mean distance error, mm); ``val/force_abs_n`` (validation
force error, N); ``speed/samples_per_s``. One quantity per plot. ``notes/i``: the run's choices
and warnings (no validation set, a loss that did not move) as text.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from core.recording import recording

APP_ID = "phantom-train"
SERIES = {
    "loss/train": ("train_loss", "train loss", (60, 120, 230)),
    "loss/val": ("val_loss", "validation loss", (230, 90, 40)),
    "val/ld_mm": ("val_ld_mm", "validation mean L_d [mm]", (40, 160, 80)),
    "val/force_abs_n": ("val_force_abs_n", "validation |dF error| [N]", (150, 60, 200)),
    "speed/samples_per_s": ("samples_per_s", "training samples/s", (120, 120, 120)),
}


def blueprint() -> rrb.Blueprint:
    return rrb.Blueprint(rrb.Vertical(
        rrb.TimeSeriesView(name="loss (88 L_d[m] + MSE[N²]) per epoch", origin="/loss"),
        rrb.Horizontal(
            rrb.TimeSeriesView(name="validation mean L_d [mm]", origin="/val/ld_mm"),
            rrb.TimeSeriesView(name="validation force error [N]", origin="/val/force_abs_n"),
            rrb.TimeSeriesView(name="training speed [samples/s]", origin="/speed"),
        ),
        row_shares=[3, 2],
    ), collapse_panels=True)


def write_train_recording(path: str | Path, log_csv: str | Path,
                          notes: Sequence[str] = ()) -> None:
    """A recording of the curves in a run's ``log.csv``, and its ``notes`` as text."""
    with open(log_csv, newline="") as f:
        rows = list(csv.DictReader(f))
    epochs = np.array([int(r["epoch"]) for r in rows])
    with recording(APP_ID, path, blueprint()) as rec:
        for entity, (col, name, color) in SERIES.items():
            rec.log(entity, rr.SeriesLines(names=[name], colors=[color]), static=True)
            values = np.array([float(r[col]) for r in rows])
            rec.send_columns(entity, indexes=[rr.TimeColumn("epoch", sequence=epochs)],
                             columns=rr.Scalars.columns(scalars=values))
        for i, note in enumerate(notes):
            level = rr.TextLogLevel.WARN if note.startswith("warning") else rr.TextLogLevel.INFO
            rec.log(f"notes/{i}", rr.TextLog(note, level=level), static=True)

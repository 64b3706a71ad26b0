"""The train stage runner: a states file and its fold manifest in; the run folder out.

Trains one fold (:func:`train.loop.train_run`: checkpoints and ``log.csv``, written atomically,
resumed when the folder holds a killed run) and records the curves (:mod:`train.train_view`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from train.loop import TrainOptions, run_notes, train_run
from train.model import CGNNConfig
from train.train_view import write_train_recording


@dataclass
class Trained:
    """What a run left: its best checkpoint, and the choices and warnings it noted."""

    best: Path
    notes: list[str]


def run_train(data: Path, splits: Path, out: Path, opts: TrainOptions, config: CGNNConfig,
              init: Path | None = None, device: str = "auto", rrd: bool = True) -> Trained:
    """Train fold ``opts.fold`` into ``out``; with ``rrd``, ``out/train.rrd`` of the curves
    and the run's notes (``--no-val``, a loss that did not move)."""
    best = train_run(data, splits, out, opts, config, init, device)
    notes = run_notes(out)
    if rrd and (out / "log.csv").is_file():
        write_train_recording(out / "train.rrd", out / "log.csv", notes)
    return Trained(best, notes)

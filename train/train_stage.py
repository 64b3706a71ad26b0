"""The train stage runner: a states file and its fold manifest in; the run folder out.

Trains one fold (:func:`train.loop.train_run`, resumed when the folder holds a killed run) into
``best.pt``, ``last.pt`` and ``log.csv``, the checkpoints written atomically with their
provenance (:data:`train.checkpoint.SCHEMA`: the command, the settings, the sha256 of the
states file, the manifest and the --init checkpoint), and the same record as
``provenance.json`` beside ``log.csv`` (the log's own provenance: its readers see a plain CSV);
then the curves' recording (:mod:`train.train_view`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch

from core.atomic import atomic_output
from core.provenance import make_provenance
from core.text import to_json
from train.checkpoint import SCHEMA
from train.loop import RunFiles, TrainOptions, run_notes, train_run
from train.model import CGNNConfig
from train.train_view import write_train_recording

PROVENANCE = "provenance.json"      # beside log.csv in the run folder


@dataclass(frozen=True)
class TrainInputs:
    """What a run reads: the states file, its fold manifest, and optionally the checkpoint to
    start from (transfer learning)."""

    data: Path
    splits: Path
    init: Path | None = None

    def files(self) -> list[Path]:
        return [self.data, self.splits, *([self.init] if self.init is not None else [])]


@dataclass(frozen=True)
class TrainParams:
    """Every setting of a run: the training options, the network, the device, and the name of
    the recipe they came from (recorded in the provenance; the settings are what count)."""

    options: TrainOptions = field(default_factory=TrainOptions)
    config: CGNNConfig = field(default_factory=CGNNConfig)
    device: str = "auto"
    recipe: str | None = None


@dataclass
class Trained:
    """What a run left: its best checkpoint, and the choices and warnings it noted."""

    best: Path
    notes: list[str]


def run_train(inputs: TrainInputs, out: Path, params: TrainParams | None = None,
              rrd: Path | None = None) -> Trained:
    """Train fold ``params.options.fold`` into the run folder ``out`` (the paper's settings
    without ``params``); with ``rrd``, a recording of the curves and the run's notes
    (``--no-val``, a loss that did not move)."""
    params = params or TrainParams()
    files = RunFiles.in_folder(out)
    saver = _Saver(inputs, params)
    best = train_run(inputs.data, inputs.splits, files, params.options, params.config,
                     inputs.init, params.device, saver)
    notes = run_notes(files.last)
    if saver.saved:          # the process that wrote the checkpoints (torchrun: rank 0 alone)
        with atomic_output(files.log.parent / PROVENANCE) as tmp:
            tmp.write_text(to_json(saver.record(), indent=1) + "\n")
        if rrd is not None:
            write_train_recording(rrd, files.log, notes)
    return Trained(best, notes)


class _Saver:
    """The checkpoint writer of a run: each state with the run's provenance, under a
    temporary name renamed into place. The provenance is made at the first checkpoint, so
    the inputs are hashed only once training has accepted them."""

    def __init__(self, inputs: TrainInputs, params: TrainParams) -> None:
        self.inputs, self.params = inputs, params
        self._record: dict[str, Any] | None = None

    def record(self) -> dict[str, Any]:
        if self._record is None:
            self._record = make_provenance("train", asdict(self.params), self.inputs.files(),
                                           *SCHEMA)
        return self._record

    @property
    def saved(self) -> bool:
        """Whether this process wrote a checkpoint (and so made the run's provenance)."""
        return self._record is not None

    def __call__(self, path: Path, state: dict[str, Any]) -> None:
        with atomic_output(path) as tmp:
            torch.save({**state, "provenance": self.record()}, tmp)

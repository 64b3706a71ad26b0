"""The train stage runner: a states file and its fold manifest in; the run folder out.

Trains one fold (:func:`train.training.loop.train_run`, resumed when the folder holds a killed run)
into ``best.pt``, ``last.pt`` and ``log.csv``, the checkpoints written atomically with their
provenance (:data:`train.training.checkpoint.SCHEMA`: the command, the settings, the sha256 of the
states file, the manifest and the --init checkpoint), and the same record as
``provenance.json`` beside ``log.csv`` (the log's own provenance: its readers see a plain CSV);
then ``best.pt`` again with its intervals, calibrated on the fold's validation presses
(:mod:`train.training.calibrate`), and the curves' recording (:mod:`train.training.train_view`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import torch

from core.atomic import atomic_output
from core.progress import say
from core.provenance import make_provenance
from core.text import to_json
from train.training.calibrate import calibrated_state
from train.training.checkpoint import SCHEMA, load_checkpoint
from train.training.loop import resolve_device, run_notes, train_run
from train.training.run_files import RunFiles
from train.training.train_params import TrainInputs, TrainParams
from train.training.train_view import write_train_recording

PROVENANCE = "provenance.json"      # beside log.csv in the run folder


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
        _calibrate(best, inputs, params, saver)
        with atomic_output(files.log.parent / PROVENANCE) as tmp:
            tmp.write_text(to_json(saver.record(), indent=1) + "\n")
        if rrd is not None:
            write_train_recording(rrd, files.log, notes)
    return Trained(best, notes)


def _calibrate(best: Path, inputs: TrainInputs, params: TrainParams, saver: _Saver) -> None:
    """Keep in ``best`` the intervals calibrated on the fold's validation presses
    (:mod:`train.training.calibrate`); a run without validation keeps none, and says so."""
    state = calibrated_state(load_checkpoint(best), inputs.data, inputs.splits,
                             params.options, resolve_device(params.device))
    if state is None:
        say("no validation presses: best.pt keeps no intervals")
        return
    saver(best, state)


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

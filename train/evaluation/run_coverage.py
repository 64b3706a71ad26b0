"""A run's intervals scored on its fold: their coverage on the test examples
(:mod:`train.evaluation.coverage`) and the range that coverage falls in by chance
(:mod:`train.evaluation.coverage_band`), from the run's own residuals."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from data_schema.states import example_groups
from train.data import SETS, example_pairs, role_examples
from train.evaluation.coverage import Coverage, absent, coverage
from train.evaluation.coverage_band import redrawn_counts
from train.evaluation.run_errors import LoadedRun
from train.training.calibrate import Residuals, joined, residuals


def fold_coverage(run: LoadedRun, run_dir: Path, keep: np.ndarray | None = None,
                  quiet: bool = False) -> Coverage | None:
    """The coverage of a run's intervals on its fold's test examples (those of ``keep``
    only, a mask in :func:`~train.evaluation.run_errors.example_errors`' order, where given);
    None, said in one line unless ``quiet``, where its checkpoint keeps none or ``keep`` keeps
    nothing."""
    if run.intervals is None:
        if not quiet:
            absent(str(run_dir))
        return None
    pairs = example_pairs(run.states, run.test)
    if keep is not None:
        if not keep.any():
            return None
        pairs = pairs[torch.as_tensor(keep)]
    return coverage(run.intervals, residuals(run.model, run.norm, run.states, pairs))


def coverage_and_band(run: LoadedRun, run_dir: Path
                      ) -> tuple[Coverage | None, np.ndarray | None]:
    """:func:`fold_coverage` of all the fold's test examples and :func:`fold_redraws`, the
    test examples predicted once; (None, None), said in one line, where the run keeps no
    intervals."""
    if run.intervals is None:
        absent(str(run_dir))
        return None, None
    test = residuals(run.model, run.norm, run.states, example_pairs(run.states, run.test))
    return coverage(run.intervals, test), fold_redraws(run, test)


def fold_redraws(run: LoadedRun, test: Residuals) -> np.ndarray | None:
    """The coverage of a run's fold with its calibration presses re-drawn among its held-out
    (validation and test) presses (:func:`~train.evaluation.coverage_band.redrawn_counts`),
    from the residuals of its ``test`` examples and of its validation examples; None where
    no press would be left to score (or the run keeps no intervals)."""
    if run.intervals is None:
        return None
    doc = json.loads(run.splits.read_text())
    fold = run.meta["options"]["fold"]
    groups = example_groups(run.meta["data"]["file"], doc["group_by"])
    val = role_examples(doc, fold, "val")
    held = joined([residuals(run.model, run.norm, run.states, example_pairs(run.states, val)),
                   test])
    press = np.concatenate([groups[s][ids[s]] for ids in (val, run.test) for s in SETS])
    return redrawn_counts(held, press, run.intervals.presses, fold)

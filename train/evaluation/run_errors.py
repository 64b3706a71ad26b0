"""A trained run's errors on its fold's test examples, example by example.

Per example: L_d, the mean over points of the distance between predicted and true deformed
points, and its max over points; the force error dF_pred - dF. The same for each no-learning
reference (:mod:`train.evaluation.references`), fitted on the fold's training examples, so
that every score (:mod:`train.evaluation.scoring`) stands beside theirs on the same examples.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from core.errors import BadInput
from train.data import (
    SETS,
    Batch,
    StateTensors,
    example_pairs,
    load_manifest,
    load_states,
    make_batch,
    role_examples,
)
from train.evaluation.references import NAMES, References
from train.intervals.table import IntervalTable
from train.model.normalise import Normaliser
from train.model.si_units import BatchPrediction, distances, predict
from train.training.checkpoint import load_checkpoint, model_from


@dataclass
class ExampleErrors:
    """Per test example of one run."""

    set: np.ndarray          # (E,) "single" | "multi"
    ld_mean: np.ndarray      # (E,) m
    ld_max: np.ndarray       # (E,) m
    force_err: np.ndarray    # (E,) N, predicted - true


@dataclass
class LoadedRun:
    """A run's best model with the data and test examples of its fold."""

    model: torch.nn.Module
    norm: Normaliser
    states: StateTensors
    test: dict[str, np.ndarray]      # set -> example ids
    meta: dict
    splits: Path
    train: dict[str, np.ndarray]     # set -> the training example ids of the run's fold
    intervals: IntervalTable | None = None   # calibrated on the fold's validation presses


def load_run(run_dir: Path, device: str = "cpu") -> LoadedRun:
    """The best checkpoint of ``run_dir``, its states and its fold's test examples."""
    state = load_checkpoint(run_dir / "best.pt", device)
    meta = state["meta"]
    data, splits = Path(meta["data"]["file"]), Path(meta["splits"])
    for p in (data, splits):
        if not p.is_file():
            raise BadInput(run_dir / "best.pt", f"its data {p} is gone")
    doc = load_manifest(splits, data)
    model, norm = model_from(state, device)
    opts = meta["options"]
    return LoadedRun(model, norm, load_states(data).to(device),
                     role_examples(doc, opts["fold"], "test"), meta, splits,
                     role_examples(doc, opts["fold"], "train", data, opts["train_groups"]),
                     IntervalTable.from_dict(state["intervals"]) if "intervals" in state
                     else None)


def on_lab(state: dict, data: Path, splits: Path, fold: int,
           device: str = "cpu") -> LoadedRun:
    """A model trained elsewhere (``state``: a checkpoint, as the generic model) on a lab's
    fold: its test examples as they are (zero-shot: the model's own normaliser), and the
    fold's training examples for the references that fit on them."""
    doc = load_manifest(splits, data)
    model, norm = model_from(state, device)
    return LoadedRun(model, norm, load_states(data).to(device),
                     role_examples(doc, fold, "test"), {"options": {"fold": fold}}, splits,
                     role_examples(doc, fold, "train", data))


@torch.no_grad()
def example_errors(run: LoadedRun, transform: Callable[[Batch], Batch] | None = None,
                   predictor: Callable[[Batch], BatchPrediction] | None = None, batch: int = 64
                   ) -> tuple[ExampleErrors, list[tuple[Batch, BatchPrediction]]]:
    """Errors on the test examples, each batch first moved by ``transform`` (a robustness
    test) and predicted by ``predictor`` (another precision; default: the model as it is);
    and a few (batch, prediction) pairs for the recording."""
    predictor = predictor or (lambda b: predict(run.model, run.norm, b))
    cols: dict[str, list] = {"set": [], "ld_mean": [], "ld_max": [], "force_err": []}
    shown: list[tuple[Batch, BatchPrediction]] = []
    for name in SETS:
        pairs = run.states.pairs[name][torch.as_tensor(run.test[name], dtype=torch.long)]
        for rows in pairs.split(batch):
            b = make_batch(run.states, rows)
            b = transform(b) if transform else b
            p = predictor(b)
            d = distances(p, b)
            cols["set"] += [name] * len(rows)
            cols["ld_mean"].append((d.sum(1) / b.mask.sum(1).clamp(min=1)).float().cpu().numpy())
            cols["ld_max"].append(d.amax(1).float().cpu().numpy())
            cols["force_err"].append((p.dforce - b.dforce).float().cpu().numpy())
            if len(shown) < 2:
                shown.append((b, p))
    if not cols["ld_mean"]:
        raise BadInput(run.splits, f"fold {run.meta['options']['fold']} has no test example")
    errs = ExampleErrors(np.array(cols["set"]), *(np.concatenate(cols[k]).astype(np.float64)
                                                  for k in ("ld_mean", "ld_max", "force_err")))
    return errs, shown


def reference_errors(run: LoadedRun) -> dict[str, ExampleErrors]:
    """The errors of each no-learning reference on the run's test examples, fitted on the
    training examples of its fold (the same subset the run trained on)."""
    refs = References(run.states, example_pairs(run.states, run.train))
    return {name: example_errors(run, predictor=_predicting(refs, name))[0] for name in NAMES}


def _predicting(refs: References, name: str) -> Callable[[Batch], BatchPrediction]:
    """The reference ``name``'s predictor."""
    return lambda b: refs.predict(name, b)


def test_errors(run_dir: Path, device: str = "cpu"
                ) -> tuple[ExampleErrors, LoadedRun, list[tuple[Batch, BatchPrediction]]]:
    """Errors of a run's best model on its fold's test examples, the run, and a few
    (batch, prediction) pairs for the recording."""
    run = load_run(run_dir, device)
    errs, shown = example_errors(run)
    return errs, run, shown


def subset(e: ExampleErrors, keep: np.ndarray) -> ExampleErrors:
    """The examples of ``keep`` (a mask)."""
    return ExampleErrors(e.set[keep], e.ld_mean[keep], e.ld_max[keep], e.force_err[keep])


def pool(errors: list[ExampleErrors]) -> ExampleErrors:
    """All examples of several runs (folds) as one set."""
    return ExampleErrors(*(np.concatenate([getattr(e, k) for e in errors])
                           for k in ("set", "ld_mean", "ld_max", "force_err")))

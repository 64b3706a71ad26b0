"""A trained run's intervals, calibrated on its fold's validation presses.

The validation presses are groups of the manifest (presses, or places) that the fold neither
trains nor tests on, so no frame of a calibration press is on the other side. Each of their
examples is predicted by the run's best model; every valid point's displacement error norm and
every example's |dF error| are the scores (:class:`Residuals`), with the features the bins read
(:func:`train.intervals.features.press_features`, as a predictor's lookup measures them). The
train runner stores the table (:class:`train.intervals.table.IntervalTable`) in ``best.pt``
(``intervals``), evaluation scores the test presses the same way to measure coverage.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from train.data import StateTensors, make_batch
from train.intervals.features import press_features
from train.intervals.table import IntervalTable
from train.model.normalise import Normaliser
from train.model.si_units import BatchPrediction, distances, predict
from train.training.checkpoint import model_from
from train.training.fold_data import fold_examples
from train.training.train_params import TrainOptions


@dataclass
class Residuals:
    """Scores and bin features of a set of examples: per valid point and per example."""

    point_error: np.ndarray      # (M,) m, the displacement error norm
    point_features: np.ndarray   # (M, 3) m: distance from the tip's path, depth, height
    point_example: np.ndarray    # (M,) the example each point belongs to
    force_error: np.ndarray      # (E,) N, predicted - true
    force_features: np.ndarray   # (E, 2) m: depth, height

    def subset(self, keep: np.ndarray) -> Residuals:
        """The examples of the mask ``keep`` (E,) with their points, renumbered from 0."""
        number = np.cumsum(keep) - 1
        mine = keep[self.point_example]
        return Residuals(self.point_error[mine], self.point_features[mine],
                         number[self.point_example[mine]], self.force_error[keep],
                         self.force_features[keep])


def batch_residuals(b: Any, p: BatchPrediction) -> Residuals:
    """The residuals of one predicted batch (its examples numbered from 0)."""
    err = distances(p, b).double().cpu().numpy()
    mask = b.mask.cpu().numpy()
    f = press_features(b.points.double().cpu().numpy(), mask, b.cond.double().cpu().numpy())
    ex = np.broadcast_to(np.arange(len(mask))[:, None], mask.shape)
    return Residuals(err[mask], f.of_points()[mask], ex[mask],
                     (p.dforce - b.dforce).double().cpu().numpy(), f.of_force())


def joined(parts: list[Residuals]) -> Residuals:
    """Several sets of residuals as one, their examples numbered on in turn."""
    first = np.cumsum([0] + [len(r.force_error) for r in parts[:-1]])
    numbered = [replace(r, point_example=r.point_example + k)
                for r, k in zip(parts, first, strict=True)]
    return Residuals(*(np.concatenate([getattr(r, f) for r in numbered])
                       for f in Residuals.__dataclass_fields__))


@torch.no_grad()
def residuals(model: nn.Module, norm: Normaliser, states: StateTensors, pairs: torch.Tensor,
              batch: int = 64) -> Residuals:
    """The residuals of ``model`` on the examples ``pairs`` (E, 2)."""
    parts = []
    for rows in pairs.split(batch):
        b = make_batch(states, rows)
        parts.append(batch_residuals(b, predict(model, norm, b)))
    return joined(parts)


def calibrate(model: nn.Module, norm: Normaliser, states: StateTensors, pairs: torch.Tensor,
              presses: int) -> IntervalTable:
    """The interval table of ``model`` calibrated on the examples ``pairs`` of ``presses``
    held-out presses."""
    r = residuals(model.eval(), norm, states, pairs)
    return IntervalTable.fit(r.point_error, r.point_features, np.abs(r.force_error),
                             r.force_features, presses)


def calibrated_state(state: dict[str, Any], data: Path, splits: Path, opts: TrainOptions,
                     device: str | torch.device = "cpu") -> dict[str, Any] | None:
    """``state`` (a loaded best checkpoint) with its ``intervals`` calibrated on the fold's
    validation presses; None where the run has none (``no_val``)."""
    states, _, val, _ = fold_examples(data, splits, opts)
    if len(val) == 0:
        return None
    model, norm = model_from(state, device)
    presses = len(_val_groups(splits, opts.fold))
    table = calibrate(model, norm, states.to(device), val.to(device), presses)
    return {**state, "intervals": table.to_dict()}


def _val_groups(splits: Path, fold: int) -> list:
    """The fold's validation groups (presses or places) the manifest names."""
    return json.loads(Path(splits).read_text())["folds"][fold]["val"]["groups"]

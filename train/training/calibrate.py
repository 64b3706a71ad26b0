"""A trained run's intervals, calibrated on its fold's validation presses.

The validation presses are groups of the manifest (presses, or places) that the fold neither
trains nor tests on, so no frame of a calibration press is on the other side. Each of their
examples is predicted by the run's best model; every valid point's displacement error norm and
every example's |dF error| are the scores (:class:`Residuals`), with the features the bins read
(:mod:`train.model.conformal`). The train runner stores the table in ``best.pt``
(``intervals``), evaluation scores the test presses the same way to measure coverage.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from train.data import StateTensors, make_batch
from train.model.conformal import IntervalTable, path_distance
from train.model.normalise import Normaliser, tip_height
from train.model.si_units import Prediction, distances, predict
from train.training.checkpoint import model_from
from train.training.fold_data import fold_examples
from train.training.train_params import TrainOptions


@dataclass
class Residuals:
    """Scores and bin features of a set of examples: per valid point and per example."""

    point_error: np.ndarray      # (M,) m, the displacement error norm
    point_features: np.ndarray   # (M, 3): distance from the tip's path m, depth m, height m
    point_example: np.ndarray    # (M,) the example each point belongs to
    force_error: np.ndarray      # (E,) N, predicted - true
    force_features: np.ndarray   # (E, 2): depth m, height m


def example_features(points: np.ndarray, valid: np.ndarray, cond: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per example (B) of inputs (B, N, 3) with validity (B, N) and C (B, 6): each point's
    distance from the tip's path (B, N), the press's depth (B,) and the tip start's height
    above the surface (B,) (0 where no other point is left)."""
    heights = [tip_height(c[:3], p[v]) for p, v, c in zip(points, valid, cond, strict=True)]
    return (path_distance(points, cond[:, :3], cond[:, 3:]),
            np.linalg.norm(cond[:, 3:] - cond[:, :3], axis=1),
            np.nan_to_num(np.array(heights, dtype=np.float64)))


def batch_residuals(b: Any, p: Prediction, first: int) -> Residuals:
    """The residuals of one predicted batch (examples numbered from ``first``)."""
    err = distances(p, b).double().cpu().numpy()
    mask = b.mask.cpu().numpy()
    points, cond = b.points.double().cpu().numpy(), b.cond.double().cpu().numpy()
    dist, depth, height = example_features(points, mask, cond)
    ex = np.broadcast_to(np.arange(len(mask))[:, None], mask.shape)
    feats = np.stack([dist, *np.broadcast_to(np.stack([depth, height])[:, :, None],
                                             (2, *mask.shape))], -1)
    return Residuals(err[mask], feats[mask], ex[mask] + first,
                     (p.dforce - b.dforce).double().cpu().numpy(), np.stack([depth, height], 1))


def joined(parts: list[Residuals]) -> Residuals:
    """Several batches' residuals as one."""
    return Residuals(*(np.concatenate([getattr(r, f) for r in parts])
                       for f in Residuals.__dataclass_fields__))


@torch.no_grad()
def residuals(model: nn.Module, norm: Normaliser, states: StateTensors, pairs: torch.Tensor,
              batch: int = 64) -> Residuals:
    """The residuals of ``model`` on the examples ``pairs`` (E, 2)."""
    parts, first = [], 0
    for rows in pairs.split(batch):
        b = make_batch(states, rows)
        parts.append(batch_residuals(b, predict(model, norm, b), first))
        first += len(rows)
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

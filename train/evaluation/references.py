"""Predictors that learn nothing, scored beside every model on the same test examples.

A model's score never stands alone: if it does not beat these, it has learned nothing worth
shipping, whatever its absolute number (docs/ARCHITECTURE.md, "Scoring a model").

- **nothing moves**: the deformed points are the input points; the tip, where it is one of the
  points (the lab's last point, the MSM's loaded mass: a point at the tip's start), goes to the
  end of C, which the input gives. Its change of force is 0.
- **nearest press**: the displacement field (target - input, per point index) of the training
  example whose C = [tip start, tip end] is nearest, added to the test input (the tip as above;
  a point missing at either end of that example moves by 0). Its change of force is that
  example's.
- **force, linear**: least squares of the change of force on [tip end - tip start, 1] over the
  training examples (4 numbers). It predicts no displacement.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from data_schema.metrics_doc import FORCE_LINEAR, NEAREST_PRESS, NOTHING_MOVES, REFERENCES, Metrics
from train.data import Batch, StateTensors, make_batch
from train.model.si_units import BatchPrediction

NAMES = REFERENCES                                       # each reference's name, as shown
DISPLACEMENT = (NOTHING_MOVES, NEAREST_PRESS)            # the references that move points
FORCE = NAMES                                            # the references that predict a force
TIP_MATCH = 1e-7      # m: a point this close to the tip's start is the tip


def tip_points(b: Batch) -> torch.Tensor:
    """(B, N) bool: the points that are the tip (at the tip's start, valid)."""
    gap = torch.linalg.vector_norm(b.points - b.cond[:, None, :3], dim=-1)
    return (gap < TIP_MATCH) & b.mask


def with_tip(b: Batch, deformed: torch.Tensor) -> torch.Tensor:
    """``deformed`` with the tip points moved to the end of C."""
    return torch.where(tip_points(b)[..., None], b.cond[:, None, 3:], deformed)


class References:
    """The three references, fitted on one fold's training examples."""

    def __init__(self, states: StateTensors, train_pairs: torch.Tensor) -> None:
        train = make_batch(states, train_pairs)
        self.cond = train.cond.double()                                      # (T, 6)
        self.disp = torch.where(train.mask[..., None], train.target - train.points, 0.0)
        self.dforce = train.dforce
        cond = self.cond.cpu().numpy()
        lhs = np.c_[cond[:, 3:] - cond[:, :3], np.ones(len(cond))]
        # SVD least squares: the minimum-norm answer where the motions span less than 3-D
        # (presses straight down), whatever LAPACK driver torch would pick
        coef = np.linalg.lstsq(lhs, train.dforce.double().cpu().numpy(), rcond=None)[0]
        self.coef = torch.from_numpy(coef).to(self.cond.device)

    def predict(self, name: str, b: Batch) -> BatchPrediction:
        """One reference's prediction for a batch (points NaN for :data:`FORCE_LINEAR`)."""
        if name == NOTHING_MOVES:
            return BatchPrediction(with_tip(b, b.points), torch.zeros_like(b.dforce))
        if name == NEAREST_PRESS:
            near = torch.cdist(b.cond.double(), self.cond).argmin(dim=1)     # (B,)
            return BatchPrediction(with_tip(b, b.points + self.disp[near]), self.dforce[near])
        if name == FORCE_LINEAR:
            step = (b.cond[:, 3:] - b.cond[:, :3]).double()
            df = step @ self.coef[:3] + self.coef[3]
            return BatchPrediction(torch.full_like(b.points, float("nan")), df.to(b.dforce.dtype))
        raise KeyError(name)


def best_reference(refs: dict[str, Metrics], value: Callable[[Metrics], float | None],
                   names: tuple[str, ...]) -> tuple[str | None, float | None]:
    """The name and ``value`` of the reference among ``names`` whose ``value`` (of its
    metrics, by name in ``refs``) is lowest; (None, None) where none has a finite one."""
    scored = [(value(refs[n]), n) for n in names if n in refs and _finite(value(refs[n]))]
    if not scored:
        return None, None
    lowest, name = min(scored)
    return name, lowest


def _finite(value: float | None) -> bool:
    return value is not None and bool(np.isfinite(value))

"""The cGNN in SI units: metres in, metres and newtons out, and the errors measured in them.

The network learns in normalised units (:mod:`train.model.normalise`); everything that runs or
scores a model converts through this one module, so the conversion is written once: training
and evaluation (:func:`predict`, :func:`distances`, :func:`mean_distance`, :func:`loss_sum`),
the predictor's SI model (:mod:`train.inference.si_model`) and the benchmarks.
``neighbours`` (B, N, k), optional, is the first layer's graph: the kNN of the points, which a
caller that keeps the same mesh from call to call computes once.

Loss (paper, "Loss Function"): ``alpha * L_d + MSE(dF)`` with ``L_d`` the mean Euclidean
distance between predicted and true deformed points, in metres, and the force change in
newtons; alpha = 88 (the paper's weight). The "balanced" loss puts each term in its training
scale instead.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import overload

import torch
from torch import nn

from train.data import Batch
from train.model.normalise import Normaliser

MIN_PRESS = 1e-9      # m: the gate's ramp where the checkpoint has no training envelope
GATE_SHARE = 0.1      # of the shortest training press: the gate's ramp


@dataclass
class BatchPrediction:
    """Model outputs in SI units."""

    deformed: torch.Tensor   # (B, N, 3) m
    dforce: torch.Tensor     # (B,) N


def press_gate(norm: Normaliser, condition: torch.Tensor) -> torch.Tensor:
    """The no-motion gate (B,): ``min(1, |tip end - tip start| / ramp)``, the ramp
    ``GATE_SHARE`` of the shortest training press.

    Every output is multiplied by it, so a tip that does not move moves no point and changes
    no force, by construction (in torch, in the ONNX graph, in every entry), and a press far
    shorter than any learned shrinks linearly to nothing (small strains are linear). It is 1
    on every press of at least a tenth of the shortest learned: training is unchanged, and so
    is a held-out press a little shorter than the training ones (it is flagged by
    :class:`train.Predictor`, not scaled). A checkpoint without the training envelope takes
    ``MIN_PRESS``: a step from 0 to 1."""
    shortest = norm.envelope.press_min if norm.envelope is not None else 0.0
    ramp = max(GATE_SHARE * shortest, MIN_PRESS)
    length = torch.linalg.vector_norm(condition[..., 3:] - condition[..., :3], dim=-1)
    return torch.clamp(length / ramp, max=1.0)


def in_si(model: nn.Module, norm: Normaliser, points: torch.Tensor, condition: torch.Tensor,
          mask: torch.Tensor | None = None, neighbours: torch.Tensor | None = None
          ) -> tuple[torch.Tensor, torch.Tensor]:
    """Deformed points (B, N, 3) m and the change of force (B,) N from points (B, N, 3) m and
    C (B, 6) m: normalise, run ``model`` (a :class:`CGNN`, possibly DDP-wrapped), denormalise,
    gate (:func:`press_gate`)."""
    disp, df = model(norm.points(points), norm.condition(condition), mask, neighbours)
    return in_metres(norm, points, disp, df, condition)


@overload
def in_metres(norm: Normaliser, points: torch.Tensor, disp: torch.Tensor,
              df: torch.Tensor, condition: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]: ...
@overload
def in_metres(norm: Normaliser, points: torch.Tensor, disp: None,
              df: torch.Tensor, condition: torch.Tensor) -> tuple[None, torch.Tensor]: ...
def in_metres(norm: Normaliser, points: torch.Tensor, disp: torch.Tensor | None,
              df: torch.Tensor, condition: torch.Tensor
              ) -> tuple[torch.Tensor | None, torch.Tensor]:
    """The network's normalised outputs as deformed points (B, N, 3) m (None when ``disp``
    is) and the change of force (B,) N, gated by the press (:func:`press_gate`)."""
    gate = press_gate(norm, condition)
    return (None if disp is None else deformed(points, disp, norm, gate),
            newtons(df, norm, gate))


def deformed(points: torch.Tensor, disp: torch.Tensor, norm: Normaliser,
             gate: torch.Tensor | None = None) -> torch.Tensor:
    """The deformed points (B, N, 3) m: ``points`` moved by the network's normalised
    displacement ``disp`` (B, N, 3), scaled by ``norm`` and by ``gate`` (B,) where given."""
    scale = norm.disp_scale if gate is None else gate.view(-1, 1, 1) * norm.disp_scale
    return points + disp * scale


def newtons(df: torch.Tensor, norm: Normaliser, gate: torch.Tensor | None = None
            ) -> torch.Tensor:
    """The change of force (B,) N from the network's normalised one, scaled by ``norm`` and
    by ``gate`` (B,) where given."""
    return df * (norm.force_scale if gate is None else gate * norm.force_scale)


def predict(model: nn.Module, norm: Normaliser, b: Batch) -> BatchPrediction:
    """Deformed points and change of force for a batch."""
    return BatchPrediction(*in_si(model, norm, b.points, b.cond, b.mask))


def distances(p: BatchPrediction, b: Batch) -> torch.Tensor:
    """(B, N) Euclidean distance of each predicted point from the truth (0 where masked)."""
    return torch.linalg.vector_norm(p.deformed - b.target, dim=-1) * b.mask


def mean_distance(p: BatchPrediction, b: Batch) -> torch.Tensor:
    """L_d per example (B,): the mean over its valid points."""
    return distances(p, b).sum(1) / b.mask.sum(1).clamp(min=1)


def loss_sum(p: BatchPrediction, b: Batch, alpha: float, norm: Normaliser | None = None,
             force_weight: torch.Tensor | None = None) -> torch.Tensor:
    """Sum over the batch of ``alpha * L_d + (dF error)^2`` (divide by the count for the mean).

    With ``norm`` (the "balanced" loss) each term is in its training scale instead:
    ``L_d / disp_scale + (dF error / force_scale)^2``, so neither swamps the other whatever
    the units and data (on the MSM the paper's weights make the force term ~800x the other).
    ``force_weight`` (B,) weighs each example's force term (training's examples that may not
    teach the force: 0).
    """
    err = p.dforce - b.dforce
    force = err ** 2 if norm is None else (err / norm.force_scale) ** 2
    if force_weight is not None:
        force = force * force_weight
    if norm is None:
        return (alpha * mean_distance(p, b) + force).sum()
    return (mean_distance(p, b) / norm.disp_scale + force).sum()



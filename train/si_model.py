"""The cGNN's SI face: metres in, metres and newtons out, and the errors measured in them.

The network learns in normalised units (:mod:`train.normalise`); everything that runs or scores
a model goes through this one module, so the conversion is written once: training and
evaluation (:func:`predict`, :func:`distances`, :func:`mean_distance`, :func:`loss_sum`), the
predictor and the ONNX export (:class:`SIModel`, :func:`to_onnx`), and the benchmarks.
``neighbours`` (B, N, k), optional, is the first layer's graph: the kNN of the points, which a
caller that keeps the same mesh from call to call computes once.

Loss (paper, "Loss Function"): ``alpha * L_d + MSE(dF)`` with ``L_d`` the mean Euclidean
distance between predicted and true deformed points, in metres, and the force change in
newtons; alpha = 88 (the paper's weight). The "balanced" loss puts each term in its training
scale instead.
"""

from __future__ import annotations

import io
import warnings
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn

from train.data import Batch
from train.model import CGNN
from train.normalise import Normaliser

OPSET = 17


@dataclass
class Prediction:
    """Model outputs in SI units."""

    deformed: torch.Tensor   # (B, N, 3) m
    dforce: torch.Tensor     # (B,) N


def in_si(model: nn.Module, norm: Normaliser, points: torch.Tensor, condition: torch.Tensor,
          mask: torch.Tensor | None = None, neighbours: torch.Tensor | None = None
          ) -> tuple[torch.Tensor, torch.Tensor]:
    """Deformed points (B, N, 3) m and the change of force (B,) N from points (B, N, 3) m and
    C (B, 6) m: normalise, run ``model`` (a :class:`CGNN`, possibly DDP-wrapped), denormalise."""
    disp, df = model(norm.points(points), norm.condition(condition), mask, neighbours)
    return points + disp * norm.disp_scale, df * norm.force_scale


def predict(model: nn.Module, norm: Normaliser, b: Batch) -> Prediction:
    """Deformed points and change of force for a batch."""
    return Prediction(*in_si(model, norm, b.points, b.cond, b.mask))


def distances(p: Prediction, b: Batch) -> torch.Tensor:
    """(B, N) Euclidean distance of each predicted point from the truth (0 where masked)."""
    return torch.linalg.vector_norm(p.deformed - b.target, dim=-1) * b.mask


def mean_distance(p: Prediction, b: Batch) -> torch.Tensor:
    """L_d per example (B,): the mean over its valid points."""
    return distances(p, b).sum(1) / b.mask.sum(1).clamp(min=1)


def loss_sum(p: Prediction, b: Batch, alpha: float, norm: Normaliser | None = None
             ) -> torch.Tensor:
    """Sum over the batch of ``alpha * L_d + (dF error)^2`` (divide by the count for the mean).

    With ``norm`` (the "balanced" loss) each term is in its training scale instead:
    ``L_d / disp_scale + (dF error / force_scale)^2``, so neither swamps the other whatever
    the units and data (on the MSM the paper's weights make the force term ~800x the other).
    """
    if norm is None:
        return (alpha * mean_distance(p, b) + (p.dforce - b.dforce) ** 2).sum()
    return (mean_distance(p, b) / norm.disp_scale
            + ((p.dforce - b.dforce) / norm.force_scale) ** 2).sum()


class SIModel(nn.Module):
    """The network with its normaliser folded in."""

    def __init__(self, model: CGNN, norm: Normaliser) -> None:
        super().__init__()
        self.model, self.norm = model, norm

    def forward(self, points: torch.Tensor, condition: torch.Tensor,
                neighbours: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Deformed points (B, N, 3) m and the change of force (B,) N."""
        return in_si(self.model, self.norm, points, condition, None, neighbours)

    def force(self, points: torch.Tensor, condition: torch.Tensor,
              neighbours: torch.Tensor | None = None) -> torch.Tensor:
        """The change of force (B,) N alone: the displacement head is not run."""
        n = self.norm
        return self.model.forward_force(n.points(points), n.condition(condition), None,
                                        neighbours) * n.force_scale


class ForceOnly(nn.Module):
    """:meth:`SIModel.force` as a module's forward (what an exporter traces)."""

    def __init__(self, si: SIModel) -> None:
        super().__init__()
        self.si = si

    def forward(self, points: torch.Tensor, condition: torch.Tensor,
                neighbours: torch.Tensor | None = None) -> torch.Tensor:
        return self.si.force(points, condition, neighbours)


def to_onnx(si: SIModel, out: str | Path | io.BytesIO, *, force_only: bool = False,
            with_neighbours: bool = False, example_points: int = 26) -> None:
    """Trace ``si`` (or its force alone) to ONNX, N a dynamic axis. ``with_neighbours`` adds
    the input ``neighbours`` (1, N, k) int64, the first layer's graph, given by the caller."""
    module = ForceOnly(si) if force_only else si
    k = si.model.config.k
    points = torch.rand(1, example_points, 3) * 0.1
    args: tuple = (points, torch.rand(1, 6) * 0.1)
    names = ["points", "condition"]
    axes = {"points": {1: "N"}}
    if with_neighbours:
        args += (torch.cdist(points, points).topk(k, largest=False).indices,)
        names.append("neighbours")
        axes["neighbours"] = {1: "N"}
    outputs = ["dforce"] if force_only else ["deformed", "dforce"]
    if not force_only:
        axes["deformed"] = {1: "N"}
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)     # the TorchScript exporter
        torch.onnx.export(module.eval(), args, out if isinstance(out, io.BytesIO) else str(out),
                          input_names=names, output_names=outputs, opset_version=OPSET,
                          dynamic_axes=axes, dynamo=False)

"""The cGNN in SI units: metres in, metres and newtons out, normalisation inside.

The network learns in normalised units (:mod:`train.normalise`); everything that uses a trained
model (the predictor, the ONNX export) goes through this one module, so the conversion is
written once. ``neighbours`` (1, N, k), optional, is the first layer's graph: the kNN of the
points, which a caller that keeps the same mesh from call to call computes once.
"""

from __future__ import annotations

import io
import warnings
from pathlib import Path

import torch
from torch import nn

from train.model import CGNN
from train.normalise import Normaliser

OPSET = 17


class SIModel(nn.Module):
    """The network with its normaliser folded in."""

    def __init__(self, model: CGNN, norm: Normaliser) -> None:
        super().__init__()
        self.model, self.norm = model, norm
        self.register_buffer("centre", torch.tensor(norm.centre, dtype=torch.float32))

    def _inputs(self, points: torch.Tensor, condition: torch.Tensor
                ) -> tuple[torch.Tensor, torch.Tensor]:
        p = (points - self.centre) / self.norm.scale
        c = (condition.reshape(-1, 2, 3) - self.centre) / self.norm.scale
        return p, c.reshape(-1, 6)

    def forward(self, points: torch.Tensor, condition: torch.Tensor,
                neighbours: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Deformed points (B, N, 3) m and the change of force (B,) N."""
        disp, df = self.model(*self._inputs(points, condition), None, neighbours)
        return points + disp * self.norm.disp_scale, df * self.norm.force_scale

    def force(self, points: torch.Tensor, condition: torch.Tensor,
              neighbours: torch.Tensor | None = None) -> torch.Tensor:
        """The change of force (B,) N alone: the displacement head is not run."""
        return self.model.forward_force(*self._inputs(points, condition), None,
                                        neighbours) * self.norm.force_scale


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

"""Export a trained cGNN to ONNX, the format game engines' inference runtimes load.

The exported graph takes SI inputs and gives SI outputs (normalisation inside): ``points``
(1, N, 3) metres in the phantom frame with N free, ``condition`` (1, 6) metres; outputs
``deformed`` (1, N, 3) metres and ``dforce`` (1,) newtons.
"""

from __future__ import annotations

from pathlib import Path

import torch
from torch import nn

from core.atomic import atomic_output
from train.checkpoint import load_checkpoint, model_from
from train.normalise import Normaliser

OPSET = 17


class SIModel(nn.Module):
    """The network with its normalisation folded in: metres in, metres and newtons out."""

    def __init__(self, model: nn.Module, norm: Normaliser) -> None:
        super().__init__()
        self.model = model
        self.register_buffer("centre", torch.tensor(norm.centre, dtype=torch.float32))
        self.scale, self.disp_scale, self.force_scale = norm.scale, norm.disp_scale, \
            norm.force_scale

    def forward(self, points: torch.Tensor, condition: torch.Tensor
                ) -> tuple[torch.Tensor, torch.Tensor]:
        p = (points - self.centre) / self.scale
        c = (condition.reshape(-1, 2, 3) - self.centre) / self.scale
        disp, df = self.model(p, c.reshape(-1, 6))
        return points + disp * self.disp_scale, df * self.force_scale


def export_onnx(run: str | Path, out: str | Path, example_points: int = 26) -> None:
    """Write ``out`` (ONNX) from a run folder or checkpoint, N a dynamic axis."""
    run = Path(run)
    model, norm = model_from(load_checkpoint(run / "best.pt" if run.is_dir() else run))
    si = SIModel(model, norm).eval()
    points = torch.rand(1, example_points, 3) * 0.1
    cond = torch.rand(1, 6) * 0.1
    with atomic_output(out) as tmp, torch.no_grad():
        torch.onnx.export(si, (points, cond), str(tmp), input_names=["points", "condition"],
                          output_names=["deformed", "dforce"], opset_version=OPSET,
                          dynamic_axes={"points": {1: "N"}, "deformed": {1: "N"}},
                          dynamo=False)

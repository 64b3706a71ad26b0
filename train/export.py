"""Export a trained cGNN to ONNX, the format game engines' inference runtimes load.

The exported graph takes SI inputs and gives SI outputs (normalisation inside, from
:mod:`train.si_model`): ``points`` (1, N, 3) metres in the phantom frame with N free,
``condition`` (1, 6) metres; outputs ``deformed`` (1, N, 3) metres and ``dforce`` (1,) newtons.
A noCond model reads no condition, and its graph has no such input.
"""

from __future__ import annotations

from pathlib import Path

from core.atomic import atomic_output
from train.checkpoint import load_checkpoint, model_from
from train.si_model import SIModel, to_onnx


def export_onnx(run: str | Path, out: str | Path) -> None:
    """Write ``out`` (ONNX) from a run folder or checkpoint, N a dynamic axis."""
    run = Path(run)
    si = SIModel(*model_from(load_checkpoint(run / "best.pt" if run.is_dir() else run)))
    with atomic_output(out) as tmp:
        to_onnx(si, tmp)

"""The export stage runner: a trained run in, its ONNX model out (:mod:`train.export`).

The model takes and gives SI values (normalisation inside the graph), N points free; the file
is written atomically. Export has no recording: the model file is what a runtime loads.
"""

from __future__ import annotations

from pathlib import Path

from train.export import export_onnx


def run_export(run: Path, onnx_path: Path) -> None:
    """Write ``onnx_path`` from ``run`` (a run folder's best.pt, or a checkpoint file)."""
    export_onnx(run, onnx_path)

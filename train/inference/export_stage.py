"""The export stage runner: a trained run in, its ONNX model out (:mod:`train.inference.export`).

The model takes and gives SI values (normalisation inside the graph), N points free; the file
is written atomically, with its provenance (:data:`SCHEMA`: the command and the sha256 of the
checkpoint) as JSON in the model's ``metadata_props["provenance"]``. Export has no recording:
the model file is what a runtime loads.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

from core.atomic import atomic_output
from core.errors import BadInput
from core.provenance import make_provenance
from core.text import to_json
from train.inference.export import checkpoint_of, export_onnx
from train.inference.export_params import ExportParams

SCHEMA = ("phantom.onnx", "1.0")     # the name and version its provenance records


def run_export(inputs: Path, out: Path, params: ExportParams | None = None,
               rrd: None = None) -> None:
    """Write the ONNX model ``out`` from ``inputs`` (a run folder's best.pt, or a checkpoint
    file). Export has no recording: ``rrd`` must be None."""
    if rrd is not None:
        raise ValueError("export writes no recording")
    params = params or ExportParams()
    checkpoint = checkpoint_of(inputs)
    if not checkpoint.is_file():
        raise BadInput(checkpoint, "no such checkpoint")
    record = make_provenance("export", asdict(params), [checkpoint], *SCHEMA)
    with atomic_output(out) as tmp:
        export_onnx(checkpoint, tmp, {"provenance": to_json(record)})

"""``pipeline export``: the click layer over :func:`train.inference.export_stage.run_export`."""

from __future__ import annotations

from pathlib import Path

import click


@click.command()
@click.argument("run", type=click.Path(exists=True, path_type=Path))
@click.option("--onnx", "onnx_path", required=True,
              type=click.Path(dir_okay=False, path_type=Path), help="ONNX model to write.")
def export(run: Path, onnx_path: Path) -> None:
    """Export a trained model for VR runtimes (ONNX, as game engines load).

    Reads RUN (a run folder from `pipeline train`, its best.pt, or a checkpoint file). Writes
    --onnx: inputs `points` (1, N, 3) m in the phantom frame (N free) and `condition` (1, 6) m;
    outputs `deformed` (1, N, 3) m and `dforce` (1,) N; normalisation is inside the graph;
    the metadata hold the guards the graph lacks, the training envelope and the provenance.
    """
    from train.inference.export_params import ExportParams
    from train.inference.export_stage import run_export

    run_export(run, onnx_path, ExportParams())
    click.echo(f"{onnx_path}: ONNX model of {run}")

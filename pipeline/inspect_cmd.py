"""``pipeline inspect``: the click layer over :func:`ingest.inspect_stage.run_inspect`."""

from __future__ import annotations

import json
from pathlib import Path

import click


@click.command()
@click.argument("file", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON (stable keys).")
def inspect(file: Path, as_json: bool) -> None:
    """Summarise FILE: format, frames, rate, marker/body/channel names, missing samples, units,
    schema version and provenance.

    Reads any lab file (QTM TSV 3D/6D, QTM analog and force-plate TSV, C3D, QTM MAT, force
    logs: CSV in any common dialect, ATI DAQ F/T and Net F/T CSV, Simulink/Speedgoat MAT arrays
    and structs v4/v7/v7.3, Parquet; ATI .cal; a session.toml beside a log says how to read it)
    and any file the pipeline writes (raw MCAP, HDF5 outputs, JSON manifests, .rrd recordings).
    Writes nothing; prints text, or with --json one JSON object whose keys are the same for
    every format (null where a key does not apply).
    """
    from ingest.inspect_stage import run_inspect
    from ingest.inspect_view import format_summary

    summary = run_inspect(file)
    if as_json:
        click.echo(json.dumps(summary, indent=2, default=str))
    else:
        click.echo(format_summary(summary))

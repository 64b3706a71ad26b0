"""``pipeline ingest``: the click layer over :func:`ingest.ingest_stage.run_ingest`."""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from core.text import count
from ingest.ingest_params import COMPRESSIONS, IngestParams
from pipeline.options import resolve_rrd, rrd_option

NONE, ZSTD = COMPRESSIONS


@click.command()
@click.argument("session_dir", type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option("--out", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="MCAP file to write (raw streams, each on its own clock).")
@click.option("--zstd", is_flag=True,
              help="zstd-compress the MCAP chunks: about half the size, ingest ~2x slower.")
@rrd_option
def ingest(session_dir: Path, out: Path, zstd: bool, rrd: Path | None, no_rrd: bool) -> None:
    """Store a raw lab session as one MCAP file of raw streams.

    Reads SESSION_DIR/session.toml and the files it names: the mocap 3D export (QTM TSV, C3D
    or QTM MAT), an optional QTM 6D export and pivot recording, the force log (CSV, MAT or
    Parquet) and the ATI .cal calibration. Checks them against the session (named markers and
    columns present, no duplicates, 6x6 calibration, increasing time) and writes --out (MCAP:
    /mocap/markers, /force/raw, ... each on its device clock, with session, calibration and
    provenance metadata) and a rerun recording of the raw trajectories and force (--rrd,
    default beside --out). Inputs are never modified; nothing is written on bad input.
    """
    from ingest.ingest_stage import run_ingest

    rrd_path = resolve_rrd(out, rrd, no_rrd)
    s = run_ingest(session_dir, out, IngestParams(compression=ZSTD if zstd else NONE), rrd_path)
    m, f = s.markers, s.force
    click.echo(f"{out}: {m.frames} mocap frames ({len(m.labels)} markers, {m.rate_hz:g} Hz, "
               f"{m.missing_samples()} missing samples{_holes(m.time_ns)}), {f.frames} force "
               f"samples ({f.kind}, {f.rate_hz:g} Hz{_holes(f.time_ns)})"
               + (f"; recording {rrd_path}" if rrd_path else ""))


def _holes(time_ns: np.ndarray) -> str:
    """", 1 hole (0.400 s)" for a stream with holes (sync names each and leaves out the
    presses they touch)."""
    from ingest.inspect_lab import holes

    found = holes(time_ns)
    return f", {count(len(found), 'hole')} ({'; '.join(found)})" if found else ""

"""The sync stage runner: ingest's MCAP in, the synced file and its recording out.

The math is :func:`sync.sync.sync_session`; this reads the input, records the provenance and
writes both outputs atomically (nothing is written unless everything succeeds).
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

from core.atomic import atomic_outputs
from core.errors import BadInput
from core.provenance import make_provenance
from data_schema.synced import SYNCED
from ingest.mcap_io import read_raw_mcap
from sync.sync import SyncResult, sync_session
from sync.sync_params import SyncParams
from sync.sync_view import write_sync_recording
from sync.synced_file import write_synced


def run_sync(inputs: str | Path, out: str | Path, params: SyncParams | None = None,
             rrd: str | Path | None = None) -> SyncResult:
    """Read ingest's MCAP ``inputs``, synchronise it, write ``out`` (and the recording)
    atomically. The settings are checked by :func:`sync.sync.sync_session`, so that every
    caller of the math gets the check (the command line refuses them earlier, as it parses)."""
    mcap, p = inputs, params or SyncParams()
    finals = {Path(x).resolve() for x in (out, rrd) if x is not None}
    if Path(mcap).resolve() in finals:
        raise BadInput(mcap, "output would overwrite the input file")
    raw = read_raw_mcap(mcap)
    result = sync_session(raw, p)
    prov = make_provenance("sync", asdict(p), [mcap], SYNCED.name, SYNCED.version)
    with atomic_outputs(out, rrd) as (tmp_out, tmp_rrd):
        write_synced(tmp_out, result, prov, Path(mcap).name)
        if tmp_rrd is not None:
            write_sync_recording(result, tmp_rrd)
    return result

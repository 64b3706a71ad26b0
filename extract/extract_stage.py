"""The extract stage runner: synced files in, the states file and its recording out.

Reads every synced file (:mod:`extract.synced_presses`), extracts the states
(:func:`extract.extract.extract`), and writes the states file (``phantom.states``, validated in
layout and meaning) and the recording (:mod:`extract.extract_view`) atomically, with the
provenance: nothing is written unless everything succeeds.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from core.atomic import atomic_outputs
from core.provenance import make_provenance
from data_schema.hdf5 import write_h5
from data_schema.states import STATES, validate_states
from extract.extract import Extracted, extract
from extract.extract_params import ExtractParams
from extract.extract_view import write_extract_recording
from extract.synced_presses import Session, read_synced


def run_extract(inputs: Sequence[str | Path], out: str | Path,
                params: ExtractParams | None = None, rrd: str | Path | None = None
                ) -> Extracted:
    """Extract the states of the synced files ``inputs`` into ``out`` (and the recording
    ``rrd``); ``params.size_m`` overrides the footprint the synced files' layout states."""
    synced, params = inputs, params or ExtractParams()
    sessions = [read_synced(path, params.size_m) for path in synced]
    ex = extract(sessions, params)
    write_states(ex, sessions, params, make_provenance("extract", asdict(params), synced,
                                                       STATES.name, STATES.version), out, rrd)
    return ex


def write_states(ex: Extracted, sessions: Sequence[Session], params: ExtractParams,
                 provenance: dict, out: str | Path, rrd: str | Path | None) -> None:
    """The states file (validated) and its recording, both or neither (``pipeline live``
    writes its online states here too)."""
    first = sessions[0]
    attrs = {**_attrs(ex, params, provenance), "point_names": json.dumps(first.point_names),
             "footprint_m": np.asarray(first.layout.size_m, dtype=float)}
    with atomic_outputs(out, rrd) as (tmp_out, tmp_rrd):
        write_h5(tmp_out, STATES, ex.arrays, attrs)
        validate_states(tmp_out)
        if tmp_rrd is not None:
            write_extract_recording(tmp_rrd, ex.sessions, first.layout.size_m,
                                    first.layout.shape)


def _attrs(ex: Extracted, params: ExtractParams, provenance: dict) -> dict[str, Any]:
    """The root attributes every lab states file has."""
    return {"provenance": json.dumps(provenance), "source": "lab", "units_length": "m",
            "units_force": "N", "step_n": params.step_n, "frame": "phantom",
            "session_names": json.dumps(ex.session_names),
            "excluded": json.dumps(ex.excluded)}

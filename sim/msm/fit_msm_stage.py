"""The fit-msm stage runner: measured states in, the fitted constants and their recording out.

Reads the states (and, with a fold manifest, only that fold's training presses), fits the
spring constants (:mod:`sim.msm.msm_fit`) and, with ``map``, a stiffness map on top of them
(:mod:`sim.msm.msm_map_fit`), and writes the ``phantom.msm_params`` JSON that
``simulate --params`` reads and the recording (:mod:`sim.msm.fit_msm_view`) atomically, with
the provenance. Its settings: :mod:`sim.msm.fit_msm_params`.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from core.atomic import atomic_outputs
from core.provenance import make_provenance
from data_schema.json_docs import MSM_PARAMS, training_sequences, validate_json_doc
from sim.msm.fit_msm_params import FitMsmInputs, FitMsmParams
from sim.msm.fit_msm_view import write_fit_recording
from sim.msm.msm import MSMParams
from sim.msm.msm_fit import FitResult, fit_msm
from sim.msm.msm_map_fit import MapResult, fit_map
from sim.msm.msm_measured import read_measured
from sim.msm.workers import default_workers


@dataclass(frozen=True)
class FitOutcome:
    """The uniform fit, and the map on top of it where one was asked for."""

    fit: FitResult
    map: MapResult | None = None


def run_fit_msm(inputs: FitMsmInputs, out: str | Path | None,
                params: FitMsmParams | None = None, rrd: str | Path | None = None
                ) -> FitOutcome:
    """Fit the MSM to ``inputs.states`` (with ``inputs.splits``: fold ``params.fold``'s
    training presses only); write the constants to ``out`` and the recording to ``rrd`` when
    given. Lab states are fitted on a grid over their footprint at ``params.spacing`` m
    (default the paper's), an MSM file on its own. The provenance records the settings with
    the contact radius the fit used (the data's where ``params.contact_radius`` is None).
    """
    p = params or FitMsmParams()
    states, splits = inputs.states, inputs.splits
    only = training_sequences(splits, p.fold, "fit-msm") if splits else None
    sequences, msm = read_measured(states, max_sequences=p.sequences_used(), seed=p.seed,
                                   contact_radius=p.contact_radius, only=only,
                                   spacing=p.spacing)
    workers = p.workers or default_workers()
    result = fit_msm(sequences, msm, start=p.start, workers=workers)
    found = None
    if p.map:
        uniform = replace(msm, k_between=result.k_between, k_fixed=result.k_fixed)
        found = fit_map(sequences, uniform, p.regions, seed=p.seed, workers=workers)
    used = replace(p, contact_radius=sequences[0].contact_radius)
    files = [states] + ([splits] if splits else [])
    with atomic_outputs(out, rrd) as (tmp_out, tmp_rrd):
        if tmp_out is not None:
            text = json.dumps(_document(result, found, msm, used, files), indent=2,
                              allow_nan=False)
            tmp_out.write_text(text + "\n")
            validate_json_doc(tmp_out, MSM_PARAMS)
        if tmp_rrd is not None:
            write_fit_recording(tmp_rrd, msm, result, sequences, found)
    return FitOutcome(result, found)


def _document(result: FitResult, found: MapResult | None, params: MSMParams,
              settings: FitMsmParams, inputs: list) -> dict:
    """The ``phantom.msm_params`` document: the fit, the map where one was fitted (also as
    ``msm_params.stiffness_map``), the full MSM parameters, provenance."""
    fitted = replace(params, k_between=result.k_between, k_fixed=result.k_fixed,
                     stiffness_map=None if found is None else
                     tuple(tuple(row) for row in found.factors))
    return {
        "schema": MSM_PARAMS.name, "schema_version": MSM_PARAMS.version,
        **asdict(result), "map": None if found is None else asdict(found),
        "msm_params": fitted.as_dict(),
        "provenance": make_provenance("fit-msm", asdict(settings), inputs=inputs),
    }

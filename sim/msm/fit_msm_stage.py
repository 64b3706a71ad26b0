"""The fit-msm stage runner: measured states in, the fitted constants and their recording out.

Reads the states (and, with a fold manifest, only that fold's training presses), fits the
spring constants (:mod:`sim.msm.msm_fit`), and writes the ``phantom.msm_params`` JSON that
``simulate --params`` reads and the recording (:mod:`sim.msm.fit_msm_view`) atomically, with
the provenance.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np

from core.atomic import atomic_outputs
from core.errors import BadInput
from core.provenance import make_provenance
from data_schema.json_docs import MSM_PARAMS, validate_folds, validate_json_doc
from sim.msm import paper
from sim.msm.fit_msm_view import write_fit_recording
from sim.msm.msm import MSMParams
from sim.msm.msm_fit import FitResult, fit_msm
from sim.msm.msm_measured import read_measured


def run_fit_msm(states: str | Path, out: str | Path | None = None,
                rrd: str | Path | None = None, *, splits: str | Path | None = None,
                fold: int = 0, max_sequences: int = 10, seed: int = 0,
                start: tuple[float, float] = (paper.K_BETWEEN, paper.K_FIXED),
                contact_radius: float | None = None, workers: int = 1,
                spacing: float | None = None) -> FitResult:
    """Fit the MSM to ``states`` (``splits``: fold ``fold``'s training presses only); write
    the constants to ``out`` and the recording to ``rrd`` when given. Lab states are fitted on
    a grid over their footprint at ``spacing`` m (default the paper's), an MSM file on its own.
    """
    only = training_sequences(splits, fold) if splits else None
    sequences, params = read_measured(states, max_sequences=max_sequences, seed=seed,
                                      contact_radius=contact_radius, only=only,
                                      spacing=spacing)
    result = fit_msm(sequences, params, start=start, workers=workers)
    settings = {"max_sequences": max_sequences, "start": list(start), "seed": seed,
                "splits": str(splits) if splits else None, "fold": fold,
                "contact_radius": sequences[0].contact_radius, "spacing": spacing}
    inputs = [states] + ([splits] if splits else [])
    with atomic_outputs(out, rrd) as (tmp_out, tmp_rrd):
        if tmp_out is not None:
            text = json.dumps(_document(result, params, settings, inputs), indent=2,
                              allow_nan=False)
            tmp_out.write_text(text + "\n")
            validate_json_doc(tmp_out, MSM_PARAMS)
        if tmp_rrd is not None:
            write_fit_recording(tmp_rrd, params, result, sequences)
    return result


def training_sequences(splits: str | Path, fold: int) -> np.ndarray:
    """The sequence ids of a fold's training presses (a manifest grouped by sequence)."""
    doc = validate_folds(splits)
    if doc.get("group_by") != "sequence":
        raise BadInput(splits, "fit-msm --splits needs a manifest grouped by sequence (press)")
    if not 0 <= fold < len(doc["folds"]):
        raise BadInput(splits, f"--fold {fold}: it has {len(doc['folds'])} folds")
    return np.asarray(doc["folds"][fold]["train"]["groups"], dtype=np.int64)


def _document(result: FitResult, params: MSMParams, settings: dict, inputs: list) -> dict:
    """The ``phantom.msm_params`` document: the fit, the full MSM parameters, provenance."""
    return {
        "schema": MSM_PARAMS.name, "schema_version": MSM_PARAMS.version,
        **asdict(result), "msm_params": {**params.as_dict(), "k_between": result.k_between,
                                         "k_fixed": result.k_fixed},
        "provenance": make_provenance("fit-msm", settings, inputs=inputs),
    }

"""The fit-solid stage runner: measured states (and the interior) in, the fitted solid out.

Reads the states (with a fold manifest, only that fold's training presses) and the interior the
session names (``session.toml``'s ``[phantom] interior`` and ``[phantom.labels]``: without one,
a uniform block) and its shape (``[phantom] shape``: a curved block in the shape's frame, the
states' own; without one, a flat block), meshes the block (:mod:`sim.solid.block_mesh`), fits
its material (:mod:`sim.solid.solid_fit`) and writes the ``phantom.solid_params`` JSON and the
recording (:mod:`sim.solid.fit_solid_view`) atomically, with the provenance. Its settings:
:mod:`sim.solid.fit_solid_params`.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from core.atomic import atomic_outputs
from core.provenance import make_provenance
from data_schema.interior import InteriorSpec, check_covers, session_interior
from data_schema.json_docs import MSM_PARAMS, SOLID_PARAMS, training_sequences, validate_json_doc
from data_schema.phantom import session_shape
from sim.solid.block_mesh import BlockGeometry
from sim.solid.fit_solid_params import FitSolidInputs, FitSolidParams
from sim.solid.fit_solid_view import write_solid_recording
from sim.solid.label_shares import label_shares
from sim.solid.measured_presses import MeasuredSet, read_presses
from sim.solid.solid_fit import Responses, SolidFit, SolidMaterial, fit_solid
from sim.solid.solid_model import SolidModel

PATCH_START = 1.2       # the contact radius starts at this many mesh spacings (the nodes
#                         beside the place share the load)


@dataclass
class SolidOutcome:
    """The fit, the MSM fit's distance where one was given (mm), and the seconds it took."""

    fit: SolidFit
    msm_mm: float | None
    seconds: float
    labels: dict[int, float | None]


def run_fit_solid(inputs: FitSolidInputs, out: str | Path | None,
                  params: FitSolidParams | None = None, rrd: str | Path | None = None
                  ) -> SolidOutcome:
    """Fit the solid to ``inputs.states`` (with ``inputs.splits``: fold ``params.fold``'s
    training presses only) with the interior of ``inputs.session``; write ``out`` and ``rrd``
    when given."""
    p = params or FitSolidParams()
    started = time.perf_counter()
    only = training_sequences(inputs.splits, p.fold, "fit-solid") if inputs.splits else None
    shape = session_shape(inputs.session) if inputs.session is not None else None
    data = read_presses(inputs.states, only, shape)
    spec = session_interior(inputs.session) if inputs.session is not None else None
    block = BlockGeometry(data.footprint, p.thickness, data.top_z, shape)
    if spec is not None:
        check_covers(spec.interior, spec.path, block.lower, block.upper)
    ratios: dict[int, float | None] = spec.ratios if spec is not None else {0: 1.0}
    model = SolidModel(block, p.spacing, p.layers)
    shares = label_shares(model.elasticity, None if spec is None else spec.interior,
                          max(ratios) + 1)
    responses = Responses(model, shares)
    fitted_labels = [k for k, r in ratios.items() if r is None]
    start = SolidMaterial(modulus=p.modulus, stiffening=p.stiffening, poisson=p.poisson,
                          ratios=tuple(1.0 if (r := ratios.get(k)) is None else r
                                       for k in range(max(ratios) + 1)),
                          contact_radius=p.contact_radius or PATCH_START * p.spacing,
                          reach=p.reach)
    fit = fit_solid(data, responses, fitted_labels, start, fit_poisson=p.fit_poisson)
    seconds = time.perf_counter() - started
    msm_mm = _msm_distance(inputs.msm)
    files = [f for f in (inputs.states, inputs.splits, inputs.msm) if f is not None] + \
        ([spec.path] if spec is not None else [])
    with atomic_outputs(out, rrd) as (tmp_out, tmp_rrd):
        if tmp_out is not None:
            doc = _document(fit, data, block, p, ratios, msm_mm, files, spec,
                            shares @ np.asarray(fit.material.ratios))
            tmp_out.write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")
            validate_json_doc(tmp_out, SOLID_PARAMS)
        if tmp_rrd is not None:
            solver = model.factorise(shares @ np.asarray(fit.material.ratios), fit.material.poisson)
            write_solid_recording(tmp_rrd, model, solver, data,
                                  responses.at(data, fit.material), fit, shares)
    return SolidOutcome(fit, msm_mm, seconds, ratios)


def _per_press(data: MeasuredSet, fit: SolidFit) -> list[dict]:
    """Each press's place (mm) and mean distance (every point, mm): over a lump or away."""
    return [{"sequence": p.sequence, "place_mm": (p.rest[-1, :2] * 1e3).round(3).tolist(),
             "all_points": float(d)} for p, d in zip(data.presses, fit.per_press_mm,
                                                      strict=True)]


def _msm_distance(path: Path | None) -> float | None:
    """fit-msm's mean distance (mm) from its JSON, to print beside the solid's."""
    if path is None:
        return None
    return float(validate_json_doc(path, MSM_PARAMS)["mean_distance_m"]) * 1e3


def _document(fit: SolidFit, data: MeasuredSet, block: BlockGeometry, p: FitSolidParams,
              ratios: dict[int, float | None], msm_mm: float | None, files: list[Path],
              spec: InteriorSpec | None, element_ratios: np.ndarray) -> dict:
    """The ``phantom.solid_params`` document: the material with its sd, the block and mesh,
    the labels (fitted or given), the distances beside the references, provenance."""
    m = fit.material
    return {
        "schema": SOLID_PARAMS.name, "schema_version": SOLID_PARAMS.version,
        "material": {"modulus_pa": m.modulus, "stiffening_per_m2": m.stiffening,
                     "poisson": m.poisson, "contact_radius_m": m.contact_radius,
                     "reach_m": m.reach,
                     "ratios": list(m.ratios)},
        "sd": fit.sd,
        "block": {"footprint_m": list(block.footprint), "thickness_m": block.thickness,
                  "top_z_m": block.top_z,
                  **({} if block.shape is None else {"shape": block.shape.as_json()})},
        "mesh": {"spacing_m": p.spacing, "layers": p.layers, "element": "hex1",
                 "element_ratios": np.round(element_ratios, 6).tolist()},
        "labels": {"interior": None if spec is None else spec.path.name,
                   "fitted": [k for k, r in ratios.items() if r is None]},
        "distances_mm": {"solid": fit.marker_mm, "tip": fit.tip_mm, "all_points": fit.all_mm,
                         "still": fit.still_mm, "msm": msm_mm,
                         "per_marker": fit.per_marker_mm.tolist(),
                         "per_press": _per_press(data, fit)},
        "provenance": make_provenance("fit-solid", asdict(p), inputs=files),
    }

"""The simulate stage runner: the MSM data set (or the join of its shards) and its recording.

Reads what the run needs (fit-msm's constants, a lab's marker layout, or the shard files),
simulates (:mod:`sim.msm.msm_dataset`) or joins (:mod:`sim.msm.msm_shards`), and writes the
states file and the recording (:mod:`sim.msm.simulate_view`) atomically, with the provenance:
nothing is written unless everything succeeds. Its settings: :mod:`sim.msm.simulate_params`.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from core.atomic import atomic_outputs
from core.errors import BadInput
from core.protocol import FOOTPRINT_M, STEP_N, THICKNESS_M
from core.provenance import make_provenance
from data_schema.json_docs import MSM_PARAMS, validate_json_doc
from data_schema.states import STATES
from sim.msm.mould_prior import MOULDS
from sim.msm.mould_prior_data import MouldRun, rest_surface, simulate_moulds
from sim.msm.msm import MSM, MSMParams
from sim.msm.msm_dataset import simulate_data, write_states
from sim.msm.msm_depth import beyond
from sim.msm.msm_grid import GRID_KEYS, check_same_grid, grid_params, recorded_grid
from sim.msm.msm_layout import LabLayout, check_inside, read_layout
from sim.msm.msm_prior import PRIOR
from sim.msm.msm_prior_data import PriorRun, simulate_prior
from sim.msm.msm_protocol import Plan, Protocol, draw_plan, parse_shard, shard_locations
from sim.msm.msm_regions import check_map
from sim.msm.msm_shards import merge_shards
from sim.msm.msm_simulate import Simulated
from sim.msm.msm_static import DEFAULT_TOL
from sim.msm.simulate_params import SimulateInputs, SimulateParams
from sim.msm.simulate_view import RestSurface, write_simulate_recording
from sim.msm.solid_states import solid_arrays
from sim.msm.workers import default_workers
from sim.solid.solid_dataset import candidate_places
from sim.solid.solid_file import read_solid
from sim.solid.solid_fit import SolidMaterial
from sim.solid.solid_model import Attachments


@dataclass
class Simulation:
    """What a run wrote, and how long the simulation (or the join) took."""

    arrays: dict[str, np.ndarray]
    seconds: float
    sim: Simulated | None = None          # None: joined from shards
    thickness: float = THICKNESS_M        # m, the phantom's
    workers: int = 1                      # processes that simulated

    @property
    def beyond_thickness(self) -> tuple[int, float]:
        """States deeper than the phantom's thickness, and the deepest depth (m)."""
        return beyond(self.arrays["states/tip"], self.thickness)


def run_simulate(inputs: SimulateInputs | None, out: str | Path,
                 params: SimulateParams | None = None, rrd: str | Path | None = None
                 ) -> Simulation:
    """Simulate the protocol of ``params`` (or its shard ``"I/N"``) into ``out`` and the
    recording ``rrd``.

    The surface covers ``params.size`` (L, W) m, else the ``inputs.layout``'s
    ``footprint_m``, else the fit's grid, else the paper's square, its masses about
    ``params.spacing`` m apart (default the paper's). ``inputs.params_file`` (fit-msm's JSON)
    overrides the spring constants and the contact radius and brings the grid they were
    fitted on (a size or spacing asking for another is refused); ``inputs.layout`` (a lab
    states file) samples the MSM at its markers. States deeper than ``params.thickness`` (m,
    the phantom's) are counted (:attr:`Simulation.beyond_thickness`). The provenance records
    ``params`` with the spring constants and contact radius the run used (the fit's).
    """
    inputs, p = inputs or SimulateInputs(), params or SimulateParams()
    if p.prior:
        return _run_prior(inputs, out, p, rrd)
    if inputs.solid is not None:
        return _run_solid(inputs, out, p, rrd)
    layout, params_file = inputs.layout, inputs.params_file
    protocol, msm = p.protocol(), MSMParams(k_between=p.k_between, k_fixed=p.k_fixed)
    lab = read_layout(layout) if layout is not None else None
    fitted = False
    if params_file is not None:
        msm, protocol, fitted = _fitted(params_file, msm, protocol)
    msm = _sized(msm, p.size, p.spacing, lab, layout, params_file if fitted else None)
    if lab is not None and layout is not None:      # a lab is read from its layout file
        check_inside(lab.points, msm, layout, lab.names)
    used = replace(p, k_between=msm.k_between, k_fixed=msm.k_fixed,
                   contact_radius=protocol.contact_radius, locations=protocol.locations,
                   directions=protocol.directions)
    shard = parse_shard(p.shard) if p.shard else None
    workers = p.workers or default_workers()
    with atomic_outputs(out, rrd) as (tmp_out, tmp_rrd):
        started = time.perf_counter()
        sim, arrays = generate(tmp_out, protocol, msm, tol=p.tol, workers=workers,
                               shard=shard, settings=used,
                               layout=None if lab is None else lab.points,
                               inputs=[Path(f) for f in (params_file, layout) if f is not None],
                               thickness=p.thickness,
                               point_names=None if lab is None else lab.point_names)
        seconds = time.perf_counter() - started
        _record(tmp_rrd, arrays, msm, protocol.step_n, p.rrd_sequences)
    return Simulation(arrays, seconds, sim, p.thickness, workers)


def generate(out: str | Path, protocol: Protocol, params: MSMParams, *,
             tol: float = DEFAULT_TOL, workers: int = 1, shard: tuple[int, int] | None = None,
             settings: SimulateParams | None = None, layout: np.ndarray | None = None,
             inputs: Sequence[Path] = (), thickness: float = THICKNESS_M,
             point_names: Sequence[str] | None = None
             ) -> tuple[Simulated, dict[str, np.ndarray]]:
    """Simulate ``protocol`` (or one shard of it, :func:`sim.msm.msm_dataset.simulate_data`)
    and write the states file ``out`` with its provenance (``settings``, default the
    :class:`SimulateParams` that ask for this protocol, model and solver; the hashes of
    ``inputs``); returns the simulation and the arrays written."""
    data = simulate_data(protocol, params, tol=tol, workers=workers, shard=shard,
                         layout=layout, thickness=thickness, point_names=point_names)
    settings = settings or SimulateParams(
        **asdict(protocol), k_between=params.k_between, k_fixed=params.k_fixed, tol=tol,
        workers=workers, shard=None if shard is None else f"{shard[0]}/{shard[1]}",
        thickness=thickness)
    prov = make_provenance("simulate", asdict(settings), inputs=list(inputs),
                           schema=STATES.name, schema_version=STATES.version)
    write_states(out, data.arrays, {"provenance": json.dumps(prov), **data.attrs})
    return data.sim, data.arrays


def _run_prior(inputs: SimulateInputs, out: str | Path, p: SimulateParams,
               rrd: str | Path | None) -> Simulation:
    """``simulate --prior``: blocks of phantoms drawn from the prior
    (:mod:`sim.msm.msm_prior_data`), or one shard of them; with ``--moulds`` curved moulds'
    solids (:mod:`sim.msm.mould_prior_data`)."""
    if inputs.layout is not None or inputs.params_file is not None:
        raise BadInput(inputs.layout or inputs.params_file,
                       "--prior draws the phantoms: no --layout or --params with it")
    locations, directions = p.places
    run = PriorRun(PRIOR, p.prior, locations, directions, p.seed)   # checks the counts
    shard = parse_shard(p.shard) if p.shard else None
    workers = p.workers or default_workers()
    used = replace(p, locations=locations, directions=directions)
    with atomic_outputs(out, rrd) as (tmp_out, tmp_rrd):
        started = time.perf_counter()
        if p.moulds:
            data = simulate_moulds(MouldRun(MOULDS, p.prior, locations, directions, p.seed),
                                   workers)
        else:
            data = simulate_prior(run, tol=p.tol, workers=workers, shard=shard)
        prov = make_provenance("simulate", asdict(used), inputs=[], schema=STATES.name,
                               schema_version=STATES.version)
        write_states(tmp_out, data.arrays, {"provenance": json.dumps(prov), **data.attrs})
        seconds = time.perf_counter() - started
        _record(tmp_rrd, data.arrays, None, STEP_N, p.rrd_sequences,
                (PRIOR.side[1], PRIOR.side[1]), rest_surface(data.arrays) if p.moulds else None)
    return Simulation(data.arrays, seconds, data.sim, p.thickness, workers)


def _run_solid(inputs: SimulateInputs, out: str | Path, p: SimulateParams,
               rrd: str | Path | None) -> Simulation:
    """``simulate --solid S --layout STATES``: the fitted solid (:mod:`sim.solid`) pressed
    by the protocol at the lab's markers, or one shard of it."""
    solid_file, layout = inputs.solid, inputs.layout
    if solid_file is None or layout is None or inputs.params_file is not None:
        raise BadInput(solid_file, "--solid simulates at a lab's markers: give --layout "
                                   "STATES, and no --params (the MSM's)")
    solid = read_solid(solid_file)
    lab = read_layout(layout, curved=solid.model.block.shape is not None)
    protocol = p.protocol()
    candidates = candidate_places(solid.model, lab.points, solid.material.contact_radius)
    if protocol.locations > len(candidates):
        raise BadInput(solid_file, f"--locations {protocol.locations}: the solid's top face has "
                                   f"{len(candidates)} nodes inside the markers' bounding box "
                                   "clear of them (fit it on a finer --spacing-mm for more)")
    plan = draw_plan(protocol, len(candidates), np.arange(len(candidates)))
    locs = shard_locations(protocol.locations, parse_shard(p.shard) if p.shard else None)
    at = Attachments.riding(lab.points, solid.model.block.top(lab.points[:, :2]))
    used = replace(p, locations=protocol.locations, directions=protocol.directions,
                   thickness=solid.model.block.thickness)
    with atomic_outputs(out, rrd) as (tmp_out, tmp_rrd):
        started = time.perf_counter()
        arrays = solid_arrays(solid.model, solid.factorise(), solid.material,
                              candidates[plan.nodes], plan, at, locs)
        prov = make_provenance("simulate", asdict(used),
                               inputs=[Path(solid_file), Path(layout)],
                               schema=STATES.name, schema_version=STATES.version)
        write_states(tmp_out, arrays, {"provenance": json.dumps(prov),
                                       **solid_attrs(plan, solid.material, lab, p.shard)})
        seconds = time.perf_counter() - started
        _record(tmp_rrd, arrays, None, protocol.step_n, p.rrd_sequences,
                lab.footprint or FOOTPRINT_M)
    return Simulation(arrays, seconds, None, solid.model.block.thickness, 1)


def solid_attrs(plan: Plan, material: SolidMaterial, lab: LabLayout, shard: str | None
                ) -> dict:
    """Root attributes of a solid states file but the provenance (shards add ``shard``)."""
    attrs = {"source": "solid", "units_length": "m", "units_force": "N",
             "step_n": plan.protocol.step_n, "frame": "phantom",
             "session_names": json.dumps(["solid"]),
             "footprint_m": np.array(lab.footprint or FOOTPRINT_M, dtype=np.float64),
             "protocol": json.dumps(asdict(plan.protocol)),
             "solid": json.dumps(asdict(material)),
             "layout": json.dumps(np.asarray(lab.points, dtype=float).round(9).tolist())}
    if lab.point_names is not None:
        attrs["point_names"] = json.dumps(lab.point_names)
    if shard is not None:
        attrs["shard"] = shard
    return attrs


def run_merge(inputs: Sequence[str | Path], out: str | Path,
              params: SimulateParams | None = None, rrd: str | Path | None = None
              ) -> Simulation:
    """Join the shard files ``inputs`` of one run into ``out`` (and the recording ``rrd``);
    of ``params`` only the recording's ``rrd_sequences`` and the ``thickness`` apply. The
    provenance records ``params`` with the protocol, the spring constants and the tolerance
    the shards were simulated with."""
    p = params or SimulateParams()
    with atomic_outputs(out, rrd) as (tmp_out, tmp_rrd):
        started = time.perf_counter()
        merged = merge_shards(inputs)
        solid = merged.attrs["source"] == "solid"
        msm = MSMParams(**json.loads(merged.attrs["msm_params"])) if \
            "blocks" not in merged.protocol and not solid else None
        if solid:                                        # shards of simulate --solid
            used = replace(p, **merged.protocol, shard=None)
        elif msm is None:                                # shards of a prior run
            run = merged.protocol
            used = replace(p, prior=run["blocks"], locations=run["locations"],
                           directions=run["directions"], seed=run["seed"], shard=None,
                           tol=json.loads(merged.attrs["solver"])["tol_N"])
        else:
            used = replace(p, **merged.protocol, k_between=msm.k_between, k_fixed=msm.k_fixed,
                           tol=json.loads(merged.attrs["solver"])["tol_N"], shard=None)
        prov = make_provenance("simulate --merge", asdict(used), inputs=merged.shards,
                               schema=STATES.name, schema_version=STATES.version)
        attrs = {**merged.attrs, "provenance": json.dumps(prov)}
        write_states(tmp_out, merged.arrays, attrs)
        seconds = time.perf_counter() - started
        _record(tmp_rrd, merged.arrays, msm, float(attrs["step_n"]), p.rrd_sequences,
                tuple(attrs["footprint_m"]))
    return Simulation(merged.arrays, seconds, thickness=p.thickness)


def _sized(params: MSMParams, size: tuple[float, float] | None, spacing: float | None,
           lab: LabLayout | None, layout: str | Path | None, fit: str | Path | None
           ) -> MSMParams:
    """``params`` on the grid asked for: ``size``, else the ``layout``'s footprint, at
    ``spacing``; unchanged where nothing asks. ``fit``: the file ``params``' grid was fitted
    on, which the grid asked for must then be (else one line naming it)."""
    asked = []
    if size is not None:
        asked.append(f"--size {size[0] * 1e3:g}x{size[1] * 1e3:g}")
    elif lab is not None and lab.footprint is not None:
        size = lab.footprint
        asked.append(f"--layout's footprint_m {size[0] * 1e3:g} x {size[1] * 1e3:g} mm")
    if spacing is not None:
        asked.append(f"--spacing-mm {spacing * 1e3:g}")
    if not asked:
        return params
    sized = grid_params(size or params.footprint, spacing, params)
    if fit is not None:
        if spacing is None:          # only a footprint was asked for: the fit's masses on it
            sized = replace(sized, n=params.n, n_y=params.n_y)
        check_same_grid(params, sized, fit, " with ".join(asked))
        return params
    return sized


def _fitted(path: str | Path, params: MSMParams, protocol: Protocol
            ) -> tuple[MSMParams, Protocol, bool]:
    """``params`` and ``protocol`` with fit-msm's spring constants, its stiffness map (a
    file without one: uniform) and contact radius, and the grid the fit was made on where
    it records one (then True)."""
    doc = validate_json_doc(path, MSM_PARAMS)
    grid = recorded_grid(doc["msm_params"], path)
    if grid is not None:
        params = replace(params, **{k: getattr(grid, k) for k in GRID_KEYS})
    return (replace(params, k_between=doc["k_between"], k_fixed=doc["k_fixed"],
                    stiffness_map=_stiffness_map(doc["msm_params"], path)),
            replace(protocol, contact_radius=float(doc.get("contact_radius_m", 0.0))),
            grid is not None)


def _stiffness_map(record: dict, path: str | Path) -> tuple | None:
    """The ``stiffness_map`` of an ``msm_params`` record (None: uniform), checked."""
    if record.get("stiffness_map") is None:
        return None
    try:
        return check_map(record["stiffness_map"])
    except BadInput as e:
        raise BadInput(path, e.what) from None


def _record(path: Path | None, arrays: dict[str, np.ndarray], params: MSMParams | None,
            step_n: float, sequences: int, footprint: tuple[float, float] = FOOTPRINT_M,
            surface: RestSurface | None = None) -> None:
    """The recording: the surface as triangles when the states are every mass of one MSM
    (``params``; None: phantoms drawn from the prior, each on its ``footprint``'s largest,
    or the solid's or merged shards' points on theirs); a mould's cap at rest under its
    points (``surface``)."""
    if path is None:
        return
    model = None if params is None else MSM(params)
    triangles = model.triangles() if model is not None and \
        arrays["states/points"].shape[1] == model.N else None
    write_simulate_recording(path, arrays, step_n, triangles,
                             footprint if params is None else params.footprint, sequences,
                             surface)

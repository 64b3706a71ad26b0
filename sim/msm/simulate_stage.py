"""The simulate stage runner: the MSM data set (or the join of its shards) and its recording.

Reads what the run needs (fit-msm's constants, a lab's marker layout, or the shard files),
simulates (:mod:`sim.msm.msm_dataset`) or joins (:mod:`sim.msm.msm_shards`), and writes the
states file and the recording (:mod:`sim.msm.simulate_view`) atomically, with the provenance:
nothing is written unless everything succeeds.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from core.atomic import atomic_outputs
from core.protocol import THICKNESS_M
from data_schema.json_docs import MSM_PARAMS, validate_json_doc
from sim.msm.msm import MSM, MSMParams
from sim.msm.msm_dataset import generate
from sim.msm.msm_depth import beyond
from sim.msm.msm_grid import GRID_KEYS, check_same_grid, grid_params, recorded_grid
from sim.msm.msm_layout import LabLayout, check_inside, read_layout
from sim.msm.msm_protocol import Protocol, parse_shard
from sim.msm.msm_shards import merge_shards
from sim.msm.msm_simulate import Simulated
from sim.msm.msm_static import DEFAULT_TOL
from sim.msm.simulate_view import write_simulate_recording


@dataclass
class Simulation:
    """What a run wrote, and how long the simulation (or the join) took."""

    arrays: dict[str, np.ndarray]
    seconds: float
    sim: Simulated | None = None          # None: joined from shards
    thickness: float = THICKNESS_M        # m, the phantom's

    @property
    def beyond_thickness(self) -> tuple[int, float]:
        """States deeper than the phantom's thickness, and the deepest depth (m)."""
        return beyond(self.arrays["states/tip"], self.thickness)


def run_simulate(out: str | Path, rrd: str | Path | None = None,
                 protocol: Protocol | None = None, params: MSMParams | None = None, *,
                 tol: float = DEFAULT_TOL, workers: int = 1, shard: str | None = None,
                 layout: str | Path | None = None, params_file: str | Path | None = None,
                 rrd_sequences: int = 4, thickness: float = THICKNESS_M,
                 size: tuple[float, float] | None = None, spacing: float | None = None
                 ) -> Simulation:
    """Simulate ``protocol`` (or shard ``"I/N"`` of it) into ``out`` and the recording ``rrd``.

    The surface covers ``size`` (L, W) m, else the ``layout``'s ``footprint_m``, else the fit's
    grid, else ``params``' (the paper's square), its masses about ``spacing`` m apart (default
    the paper's). ``params_file`` (fit-msm's JSON) overrides the spring constants and the
    contact radius and brings the grid they were fitted on (a size or spacing asking for
    another is refused); ``layout`` (a lab states file) samples the MSM at its markers.
    ``thickness`` (m, the phantom's): states deeper are counted
    (:attr:`Simulation.beyond_thickness`).
    """
    protocol, params = protocol or Protocol(), params or MSMParams()
    lab = read_layout(layout) if layout is not None else None
    fitted = False
    if params_file is not None:
        params, protocol, fitted = _fitted(params_file, params, protocol)
    params = _sized(params, size, spacing, lab, layout, params_file if fitted else None)
    if lab is not None:
        check_inside(lab.points, params, layout, lab.names)
    shard_ij = parse_shard(shard) if shard else None
    command = {**asdict(protocol), "k_between": params.k_between, "k_fixed": params.k_fixed,
               "tol": tol, "shard": shard, "layout": str(layout) if layout else None,
               "thickness": thickness, "footprint_m": list(params.footprint),
               "grid": [params.n, params.n_y]}
    inputs = [Path(p) for p in (params_file, layout) if p is not None]
    with atomic_outputs(out, rrd) as (tmp_out, tmp_rrd):
        started = time.perf_counter()
        sim, arrays = generate(tmp_out, protocol, params, tol=tol, workers=workers,
                               shard=shard_ij, command_params=command,
                               layout=None if lab is None else lab.points, inputs=inputs,
                               thickness=thickness,
                               point_names=None if lab is None else lab.point_names)
        seconds = time.perf_counter() - started
        _record(tmp_rrd, arrays, params, protocol.step_n, rrd_sequences)
    return Simulation(arrays, seconds, sim, thickness)


def run_merge(shards: Sequence[str | Path], out: str | Path, rrd: str | Path | None = None,
              rrd_sequences: int = 4, thickness: float = THICKNESS_M) -> Simulation:
    """Join the shard files of one run into ``out`` (and the recording ``rrd``)."""
    with atomic_outputs(out, rrd) as (tmp_out, tmp_rrd):
        started = time.perf_counter()
        arrays, attrs = merge_shards(shards, tmp_out)
        seconds = time.perf_counter() - started
        params = MSMParams(**json.loads(attrs["msm_params"]))
        _record(tmp_rrd, arrays, params, float(attrs["step_n"]), rrd_sequences)
    return Simulation(arrays, seconds, thickness=thickness)


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
    """``params`` and ``protocol`` with fit-msm's spring constants and contact radius, and
    the grid the fit was made on where it records one (then True)."""
    doc = validate_json_doc(path, MSM_PARAMS)
    grid = recorded_grid(doc["msm_params"], path)
    if grid is not None:
        params = replace(params, **{k: getattr(grid, k) for k in GRID_KEYS})
    return (replace(params, k_between=doc["k_between"], k_fixed=doc["k_fixed"]),
            replace(protocol, contact_radius=float(doc.get("contact_radius_m", 0.0))),
            grid is not None)


def _record(path: Path | None, arrays: dict[str, np.ndarray], params: MSMParams,
            step_n: float, sequences: int) -> None:
    """The recording: the surface as triangles when the states are every mass."""
    if path is None:
        return
    model = MSM(params)
    triangles = model.triangles() if arrays["states/points"].shape[1] == model.N else None
    write_simulate_recording(path, arrays, step_n, triangles, params.footprint, sequences)

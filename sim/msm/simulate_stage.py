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
from sim.msm.msm_layout import lab_layout
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
                 rrd_sequences: int = 4, thickness: float = THICKNESS_M) -> Simulation:
    """Simulate ``protocol`` (or shard ``"I/N"`` of it) into ``out`` and the recording ``rrd``.

    ``params_file`` (fit-msm's JSON) overrides the spring constants and the contact radius;
    ``layout`` (a lab states file) samples the MSM at its markers. ``thickness`` (m, the
    phantom's): states deeper are counted (:attr:`Simulation.beyond_thickness`).
    """
    protocol, params = protocol or Protocol(), params or MSMParams()
    if params_file is not None:
        params, protocol = _fitted(params_file, params, protocol)
    shard_ij = parse_shard(shard) if shard else None
    command = {**asdict(protocol), "k_between": params.k_between, "k_fixed": params.k_fixed,
               "tol": tol, "shard": shard, "layout": str(layout) if layout else None,
               "thickness": thickness}
    inputs = [Path(p) for p in (params_file, layout) if p is not None]
    points = lab_layout(layout) if layout is not None else None
    with atomic_outputs(out, rrd) as (tmp_out, tmp_rrd):
        started = time.perf_counter()
        sim, arrays = generate(tmp_out, protocol, params, tol=tol, workers=workers,
                               shard=shard_ij, command_params=command, layout=points,
                               inputs=inputs, thickness=thickness)
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


def _fitted(path: str | Path, params: MSMParams, protocol: Protocol
            ) -> tuple[MSMParams, Protocol]:
    """``params`` and ``protocol`` with fit-msm's spring constants and contact radius."""
    doc = validate_json_doc(path, MSM_PARAMS)
    return (replace(params, k_between=doc["k_between"], k_fixed=doc["k_fixed"]),
            replace(protocol, contact_radius=float(doc.get("contact_radius_m", 0.0))))


def _record(path: Path | None, arrays: dict[str, np.ndarray], params: MSMParams,
            step_n: float, sequences: int) -> None:
    """The recording: the surface as triangles when the states are every mass."""
    if path is None:
        return
    model = MSM(params)
    triangles = model.triangles() if arrays["states/points"].shape[1] == model.N else None
    write_simulate_recording(path, arrays, step_n, triangles, sequences)

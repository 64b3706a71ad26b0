"""The MSM data set: a simulated plan written as a states file (``phantom.states``).

Layout (same as extracted lab states): sequence ``s = location * directions + direction``
holds states ``s * (steps + 1) + t`` for t = 0 (rest) .. steps; ``tip`` is the loaded mass,
``force`` the force magnitude, ``force_vector`` the force; single-step examples are
(t, t + 1) for every t of every sequence, multi-step examples ``min(15, #pairs)`` random pairs
(start, end) with end - start >= 2 per sequence (drawn without replacement, sorted). The root
attribute ``step_n`` is the protocol's force step, ``fmax / steps``; ``footprint_m`` the MSM's
surface [L, W] (m); with a lab's layout, ``layout`` its markers' rest positions and
``point_names`` their names then "tip" (where the lab's states name them).

A shard's file (``shard=(i, count)``) is a complete states file of its block of locations;
:mod:`sim.msm.msm_shards` joins them. The runner (:mod:`sim.msm.simulate_stage`) records the
provenance and writes the file (:func:`write_states`).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from core.protocol import THICKNESS_M
from data_schema.hdf5 import write_h5
from data_schema.states import STATES, validate_states
from sim.msm.msm import MSM, MSMError, MSMParams
from sim.msm.msm_depth import check_depth, check_states_depth
from sim.msm.msm_layout import footprint
from sim.msm.msm_protocol import Plan, Protocol, draw_plan, shard_locations
from sim.msm.msm_simulate import Simulated, simulate_plan
from sim.msm.msm_static import DEFAULT_TOL, check_tol

RESIDUAL_ATTRS = ("max_residual_N", "stored_residual_N")     # merged: the largest of any shard


def states_arrays(plan: Plan, sim: Simulated) -> dict[str, np.ndarray]:
    """The states-file datasets of a simulated block of locations."""
    p = plan.protocol
    T = p.steps + 1
    seq = (sim.locations[:, None] * p.directions + np.arange(p.directions)).ravel()
    n_seq = len(seq)
    step = np.tile(np.arange(T), n_seq)
    force = (step * p.step_n).astype(np.float32)
    dirs = plan.directions[sim.locations].reshape(n_seq, 3)
    force_vector = (np.repeat(dirs, T, 0) * (step * p.step_n)[:, None])
    nodes = np.repeat(plan.nodes[sim.locations], p.directions * T)
    base = np.arange(n_seq)[:, None] * T
    single = base + np.arange(p.steps)
    multi = base[:, :, None] + plan.multi[seq]
    return {
        "states/points": sim.points,
        "states/valid": np.ones(sim.points.shape[:2], dtype=bool),
        "states/tip": sim.tips,
        "states/force": force,
        "states/force_vector": force_vector.astype(np.float32),
        "states/step": step.astype(np.int32),
        "states/sequence": np.repeat(seq, T).astype(np.int32),
        "states/location": np.repeat(seq // p.directions, T).astype(np.int32),
        "states/session": np.zeros(len(step), dtype=np.int32),
        "states/mass": nodes.astype(np.int32),
        "single/start": single.ravel().astype(np.int32),
        "single/end": (single + 1).ravel().astype(np.int32),
        "multi/start": multi[..., 0].ravel().astype(np.int32),
        "multi/end": multi[..., 1].ravel().astype(np.int32),
    }


def write_states(path: str | Path, arrays: dict[str, np.ndarray], attrs: dict) -> None:
    """Write an MSM states file atomically, validated against ``phantom.states``: every value
    finite (a point where it is valid: a prior's padding is not)."""
    for name, data in arrays.items():
        seen = arrays.get("states/valid", np.True_) if name == "states/points" else np.True_
        if data.dtype.kind == "f" and not np.isfinite(data[seen]).all():
            raise MSMError(f"refusing to write non-finite values in {name}")
    write_h5(path, STATES, arrays, attrs)
    validate_states(path)


def file_attrs(plan: Plan, params: MSMParams, tol: float, provenance: dict,
               shard: tuple[int, int] | None, sim: Simulated | None = None) -> dict:
    """Root attributes of an MSM states file: ``provenance`` first, then :func:`data_attrs`."""
    return {"provenance": json.dumps(provenance), **data_attrs(plan, params, tol, shard, sim)}


def data_attrs(plan: Plan, params: MSMParams, tol: float, shard: tuple[int, int] | None,
               sim: Simulated | None = None) -> dict:
    """Root attributes of an MSM states file but the provenance (shards add
    ``shard = "I/N"``).

    With ``sim``: ``max_residual_N``, the largest force left on any mass of any state as
    solved (float64, below ``tol``), and ``stored_residual_N``, the same of the states as
    stored: float32 rounds positions by up to ~4e-9 m at 0.1 m, which leaves ~1e-6 to 1e-5 N
    of spring force whatever ``tol`` was.
    """
    attrs = {
        "source": "msm",
        "units_length": "m",
        "units_force": "N",
        "step_n": plan.protocol.step_n,
        "frame": "phantom",
        "session_names": json.dumps(["msm"]),
        "msm_params": json.dumps(params.as_dict()),
        "footprint_m": np.array(params.footprint, dtype=np.float64),
        "protocol": json.dumps(asdict(plan.protocol)),
        "solver": json.dumps({"method": "static equilibrium (preconditioned L-BFGS)",
                              "tol_N": tol}),
        "k_between": params.k_between,
        "k_fixed": params.k_fixed,
    }
    if sim is not None:
        attrs[RESIDUAL_ATTRS[0]] = sim.max_residual
        attrs[RESIDUAL_ATTRS[1]] = sim.stored_residual
    if shard is not None:
        attrs["shard"] = f"{shard[0]}/{shard[1]}"
    return attrs


@dataclass
class MSMData:
    """A simulated block of locations, with everything its states file holds but the
    provenance (which the runner records)."""

    sim: Simulated
    arrays: dict[str, np.ndarray]
    attrs: dict               # root attributes but ``provenance`` (:func:`data_attrs`)


def simulate_data(protocol: Protocol, params: MSMParams, *, tol: float = DEFAULT_TOL,
                  workers: int = 1, shard: tuple[int, int] | None = None,
                  layout: np.ndarray | None = None, thickness: float = THICKNESS_M,
                  point_names: Sequence[str] | None = None) -> MSMData:
    """Simulate ``protocol`` (or one shard of it): the states file's arrays and attributes.

    With ``layout`` (a lab's rest points, :func:`sim.msm.msm_layout.lab_layout`) the states
    are the MSM sampled at those points plus the tip, and the loads fall inside the layout's
    footprint (where the lab pressed), so the network pre-trains on the graph it is
    fine-tuned on; ``point_names`` (the layout's names then "tip") names those points. A
    protocol that drives the MSM deeper than its surface is wide is refused before simulating
    (:mod:`sim.msm.msm_depth`; ``thickness``, the phantom's, in the message).
    """
    check_tol(tol)
    model = MSM(params)
    plan = draw_plan(protocol, model.N, None if layout is None else footprint(model, layout))
    locs = shard_locations(protocol.locations, shard)
    check_depth(plan, params, locs, thickness)
    sim = simulate_plan(plan, params, locs, tol, workers, layout)
    check_states_depth(plan, params, sim.tips, thickness)
    arrays = states_arrays(plan, sim)
    attrs = data_attrs(plan, params, tol, shard, sim)
    if layout is not None:
        attrs["layout"] = json.dumps(np.asarray(layout, dtype=float).round(9).tolist())
        if point_names is not None:
            if len(point_names) != len(layout) + 1:
                raise MSMError(f"{len(point_names)} point names for {len(layout)} layout "
                               "points and the tip")
            attrs["point_names"] = json.dumps(list(point_names))
    return MSMData(sim, arrays, attrs)

"""``simulate --prior``: the states file of blocks drawn from the prior, side by side.

Each block is one phantom drawn from :mod:`sim.msm.msm_prior`, simulated at its markers
(:func:`sim.msm.msm_dataset.simulate_data`), padded to the prior's largest marker count with
the tip last, and numbered after the blocks before it; the blocks run in worker processes and
the result does not depend on how many. The phantoms' draws are stored beside the states
(``phantoms/*``, one row a block; ``states/phantom`` each state's block), the run (the prior's
ranges, blocks, locations, directions, seed) as the root attribute ``protocol``. A shard
(``shard=(i, count)``) is a contiguous run of blocks, a complete states file that ``--merge``
joins to the bytes of a whole run.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import ClassVar

import numpy as np

from core.bounds import Bound
from core.protocol import STEP_N
from sim.msm.msm_dataset import MSMData, simulate_data
from sim.msm.msm_prior import Prior, PriorPhantom, draw_phantom, prior_record
from sim.msm.msm_protocol import shard_locations
from sim.msm.msm_simulate import Simulated
from sim.msm.msm_static import DEFAULT_TOL, check_tol
from sim.msm.workers import run_blocks

PHANTOM_FIELDS = ("k_between", "k_fixed", "contact_radius", "footprint", "markers", "pitch",
                  "scattered", "missing", "max_angle_deg")


@dataclass(frozen=True)
class PriorRun:
    """What ``simulate --prior`` simulates: ``blocks`` phantoms drawn from ``prior`` with
    ``seed``, each pressed at ``locations`` places along ``directions`` directions."""

    prior: Prior
    blocks: int
    locations: int
    directions: int
    seed: int

    # the option of ``pipeline simulate`` that sets each count (its ranges are the prior's own)
    OPTIONS: ClassVar[Mapping[str, str]] = MappingProxyType(
        {"blocks": "--prior", "locations": "--locations", "directions": "--directions"})
    BOUNDS: ClassVar[Mapping[str, Bound]] = MappingProxyType(
        {name: Bound(1, whole=True) for name in OPTIONS})

    def __post_init__(self) -> None:
        """Refuse a run that cannot be simulated, in one line naming the option that sets
        the count (a library caller is refused as the command line would be)."""
        for name, bound in self.BOUNDS.items():
            bound.check(self.OPTIONS[name], getattr(self, name))

    def as_json(self) -> dict:
        """The run as JSON values: what a states file records and its shards must share."""
        return {"prior": prior_record(self.prior), "blocks": self.blocks,
                "locations": self.locations, "directions": self.directions, "seed": self.seed}


def simulate_prior(run: PriorRun, *, tol: float = DEFAULT_TOL, workers: int = 1,
                   shard: tuple[int, int] | None = None) -> MSMData:
    """The blocks of ``run`` (or one shard of them): the states file's arrays and root
    attributes (but the provenance)."""
    check_tol(tol)
    blocks = shard_locations(run.blocks, shard)
    jobs = [(run, int(b), tol) for b in blocks]
    done = run_blocks(_simulate_block, jobs, workers, "simulating phantoms of the prior")
    parts = [arrays for arrays, _, _ in done]
    residual = max((worst for _, worst, _ in done), default=0.0)
    stored = max((kept for _, _, kept in done), default=0.0)
    arrays = joined(parts)
    sim = Simulated(blocks, arrays["states/points"], arrays["states/tip"], residual, stored,
                    0, 0, 0.0)
    return MSMData(sim, arrays, _attrs(run, tol, shard, residual, stored))


def _simulate_block(args: tuple[PriorRun, int, float]) -> tuple[dict[str, np.ndarray], float,
                                                                float]:
    """One block in a worker: its phantom drawn, simulated, padded; the solver's residuals."""
    run, block, tol = args
    phantom = draw_phantom(run.prior, run.seed, block, run.locations, run.directions)
    occlusion = np.random.default_rng([run.seed, block, 1])
    data = simulate_data(phantom.protocol, phantom.params, tol=tol, layout=phantom.layout)
    p = phantom.protocol
    arrays = padded(data.arrays, len(phantom.layout), phantom.missing,
                    p.locations * p.directions, p.locations, block, run.prior.markers[1],
                    occlusion)
    arrays.update({f"phantoms/{k}": np.asarray(v)[None] for k, v in phantom_row(phantom).items()})
    return arrays, data.sim.max_residual, data.sim.stored_residual


def padded(a: dict[str, np.ndarray], n: int, missing: float, sequences: int, locations: int,
           block: int, width: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """A block's arrays (its ``n`` markers then the tip) with ``width`` marker slots then the
    tip (the slots it lacks, and the share ``missing`` of markers ``rng`` occludes, ``valid``
    False and NaN), its ``sequences`` and ``locations`` numbered after the blocks before it
    (each block has as many)."""
    states = len(a["states/step"])
    points = np.full((states, width + 1, 3), np.nan, np.float32)
    points[:, :n], points[:, -1] = a["states/points"][:, :n], a["states/points"][:, -1]
    valid = np.zeros((states, width + 1), bool)
    valid[:, :n] = rng.random((states, n)) >= missing
    valid[:, -1] = True
    points[~valid] = np.nan
    return {**a, "states/points": points, "states/valid": valid,
            "states/sequence": a["states/sequence"] + block * sequences,
            "states/location": a["states/location"] + block * locations,
            "states/phantom": np.full(states, block, np.int32)}


def phantom_row(phantom: PriorPhantom) -> dict[str, np.generic | np.ndarray]:
    """A block's phantom as its row of the ``phantoms/*`` datasets (numbers, and the
    footprint's two sides)."""
    p, q = phantom.params, phantom.protocol
    return {"k_between": np.float64(p.k_between), "k_fixed": np.float64(p.k_fixed),
            "contact_radius": np.float64(q.contact_radius),
            "footprint": np.array(p.footprint, np.float64),
            "markers": np.int32(len(phantom.layout)), "pitch": np.float64(phantom.pitch),
            "scattered": np.bool_(phantom.scattered), "missing": np.float64(phantom.missing),
            "max_angle_deg": np.float64(q.max_angle_deg)}


def joined(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """The blocks' arrays one after the other, example indices shifted by the states before."""
    offsets = np.cumsum([0] + [len(p["states/step"]) for p in parts[:-1]])
    out = {}
    for name in parts[0]:
        shift = name.startswith(("single/", "multi/"))
        out[name] = np.concatenate([p[name] + o if shift else p[name]
                                    for p, o in zip(parts, offsets, strict=True)])
    return out


def _attrs(run: PriorRun, tol: float, shard: tuple[int, int] | None, residual: float,
           stored: float) -> dict:
    """Root attributes of a prior states file but the provenance."""
    attrs = {
        "source": "msm", "units_length": "m", "units_force": "N", "step_n": STEP_N,
        "frame": "phantom", "session_names": json.dumps(["msm prior"]),
        "msm_params": json.dumps({"prior": True}),
        "footprint_m": np.array([run.prior.side[1]] * 2, np.float64),
        "protocol": json.dumps(run.as_json()),
        "solver": json.dumps({"method": "static equilibrium (preconditioned L-BFGS)",
                              "tol_N": tol}),
        "max_residual_N": residual, "stored_residual_N": stored,
    }
    if shard is not None:
        attrs["shard"] = f"{shard[0]}/{shard[1]}"
    return attrs

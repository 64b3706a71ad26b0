"""``simulate --prior N --moulds``: the states file of curved solid phantoms drawn from the
prior over moulds (:mod:`sim.msm.mould_prior`), side by side.

Each block is one mould's solid: factorised once, its modulus set so that its centre press at
7.5 N goes as deep as drawn, pressed at its places (:func:`sim.msm.solid_states.solid_arrays`)
and laid out as the MSM prior's blocks are (padded to the prior's largest
marker count with the tip last, numbered after the blocks before it, each block's draw in
``phantoms/*``: :mod:`sim.msm.msm_prior_data`), so the trainer reads one kind of file. The run
(the prior's ranges, blocks, locations, directions, seed) is the root attribute ``protocol``,
and its ``source`` is ``moulds``: a model pre-trained on it is told from one pre-trained on a
lab's own solid (``source = "solid"``) wherever runs are named (Table 2's "Moulds").
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from core.protocol import STEP_N
from sim.msm.mould_prior import (
    Cap,
    MouldPhantom,
    MouldPrior,
    cap_surface,
    draw_mould,
    modulus_for_depth,
    mould_record,
)
from sim.msm.msm_dataset import MSMData
from sim.msm.msm_prior import PRIOR
from sim.msm.msm_prior_data import joined, padded
from sim.msm.msm_simulate import Simulated
from sim.msm.solid_states import solid_arrays
from sim.msm.workers import run_blocks
from sim.solid.elasticity import Solver
from sim.solid.fit_solid_params import FitSolidParams
from sim.solid.solid_model import Attachments

SOURCE = "moulds"     # the states' source: a prior's moulds (their solids), not a lab's solid


@dataclass(frozen=True)
class MouldRun:
    """What ``simulate --prior --moulds`` simulates: ``blocks`` moulds drawn from ``prior``
    with ``seed``, each pressed at ``locations`` places along ``directions`` directions."""

    prior: MouldPrior
    blocks: int
    locations: int
    directions: int
    seed: int

    def as_json(self) -> dict:
        """The run as JSON values: what a states file records."""
        return {"moulds": mould_record(self.prior), "blocks": self.blocks,
                "locations": self.locations, "directions": self.directions, "seed": self.seed}


def simulate_moulds(run: MouldRun, workers: int = 1) -> MSMData:
    """The blocks of ``run``: the states file's arrays and root attributes (but the
    provenance); the blocks run in ``workers`` processes and do not depend on how many."""
    parts = run_blocks(_simulate_block, [(run, b) for b in range(run.blocks)], workers,
                       "simulating moulds of the prior")
    arrays = joined(parts)
    sim = Simulated(np.arange(run.blocks), arrays["states/points"], arrays["states/tip"],
                    0.0, 0.0, 0, 0, 0.0)
    return MSMData(sim, arrays, _attrs(run))


def _simulate_block(args: tuple[MouldRun, int]) -> dict[str, np.ndarray]:
    """One block in a worker: its mould drawn, its solid factorised and pressed, padded."""
    run, block = args
    phantom = draw_mould(run.prior, run.seed, block, run.locations, run.directions)
    model, plan = phantom.model, phantom.plan
    solver = model.factorise(np.ones(model.elasticity.n_elements), FitSolidParams.poisson)
    at = phantom.at()
    modulus = centre_modulus(phantom, solver, at)
    arrays = solid_arrays(model, solver, phantom.material(modulus), phantom.places, plan, at)
    out = padded(arrays, len(phantom.layout), phantom.missing, run.locations * run.directions,
                 run.locations, block, PRIOR.markers[1],
                 np.random.default_rng([run.seed, block, 1]))
    out.update({f"phantoms/{k}": np.asarray(v)[None]
                for k, v in mould_row(phantom, modulus).items()})
    return out


def centre_modulus(phantom: MouldPhantom, solver: Solver, at: Attachments) -> float:
    """The modulus (Pa) at which the phantom's centre press, along the inward normal there,
    goes its drawn depth at 7.5 N."""
    model = phantom.model
    contact = phantom.plan.protocol.contact_radius
    resp = model.respond(solver, phantom.centre[None], contact, model.probes(at))[0]
    shape = model.block.shape
    inward = -shape.closest(phantom.centre[None])[1][0] if shape is not None \
        else np.array([0.0, 0.0, -1.0])
    return modulus_for_depth(float(np.linalg.norm(inward @ resp.tip)), phantom.depth,
                             phantom.stiffening, phantom.plan.protocol.fmax)


def mould_row(phantom: MouldPhantom, modulus: float) -> dict[str, np.generic | np.ndarray]:
    """A block's mould as its row of the ``phantoms/*`` datasets."""
    q = phantom.plan.protocol
    return {"cap": np.int32(list(Cap).index(phantom.cap)), "height": np.float64(phantom.height),
            "thickness": np.float64(phantom.thickness), "modulus": np.float64(modulus),
            "stiffening": np.float64(phantom.stiffening), "reach": np.float64(phantom.reach),
            "depth": np.float64(phantom.depth),
            "contact_radius": np.float64(q.contact_radius),
            "footprint": np.array(phantom.model.block.footprint, np.float64),
            "markers": np.int32(len(phantom.layout)), "pitch": np.float64(phantom.pitch),
            "scattered": np.bool_(phantom.scattered), "missing": np.float64(phantom.missing),
            "max_angle_deg": np.float64(q.max_angle_deg)}


def rest_surface(arrays: dict[str, np.ndarray]) -> Callable[[int], tuple[np.ndarray,
                                                                          np.ndarray]]:
    """A sequence's mould cap at rest (vertices, triangles), from its block's draw: what the
    recording draws under its markers."""
    def surface(sequence: int) -> tuple[np.ndarray, np.ndarray]:
        block = int(arrays["states/phantom"][np.flatnonzero(arrays["states/sequence"]
                                                            == sequence)[0]])
        cap = list(Cap)[int(arrays["phantoms/cap"][block])]
        size = tuple(float(v) for v in arrays["phantoms/footprint"][block])
        return cap_surface(cap, (size[0], size[1]), float(arrays["phantoms/height"][block]))
    return surface


def _attrs(run: MouldRun) -> dict:
    """Root attributes of a moulds states file but the provenance."""
    return {"source": SOURCE, "units_length": "m", "units_force": "N", "step_n": STEP_N,
            "frame": "phantom", "session_names": json.dumps(["solid prior over moulds"]),
            "footprint_m": np.array([run.prior.side[1]] * 2, np.float64),
            "protocol": json.dumps(run.as_json())}

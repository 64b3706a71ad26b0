"""The solid pressed by a plan of the MSM's protocol, as a states file's arrays: what
``simulate --solid`` writes at a lab's markers and ``simulate --prior --moulds`` per mould.

The plan's directions are drawn about -z; on a curved block each is turned about its place's
inward normal (:func:`sim.solid.solid_dataset.square_to_surface`) before it is pressed, and
the turned direction is the one recorded (``states/force_vector``): the load applied.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sim.msm.msm_dataset import states_arrays
from sim.msm.msm_protocol import Plan
from sim.msm.msm_simulate import Simulated
from sim.solid.elasticity import Solver
from sim.solid.solid_dataset import simulate_places, square_to_surface
from sim.solid.solid_fit import SolidMaterial
from sim.solid.solid_model import Attachments, SolidModel


def solid_arrays(model: SolidModel, solver: Solver, material: SolidMaterial,
                 places: np.ndarray, plan: Plan, at: Attachments,
                 locs: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """The states arrays of the plan's locations ``locs`` (default all) at ``places`` (L, 3,
    one a location), the attached points ``at`` then the tip; no ``states/mass`` (no mass is
    loaded)."""
    locs = np.arange(len(places)) if locs is None else locs
    plan = replace(plan, directions=square_to_surface(model, places, plan.directions))
    forces = np.arange(plan.protocol.steps + 1) * plan.protocol.step_n
    states = simulate_places(model, solver, material, places[locs], plan.directions[locs],
                             forces, at)
    sim = Simulated(locs, states.points, states.tips, 0.0, 0.0, 0, 1, 0.0)
    return {k: v for k, v in states_arrays(plan, sim).items() if k != "states/mass"}

"""The MSM's depth against the phantom: how deep the loaded surface goes, and what is refused.

The surface model has no floor: a large enough force (or soft enough springs) pushes the
loaded mass arbitrarily deep (the paper's constants at 100 N: 280-830 mm). Two bounds:

- deeper than the MSM's own surface is wide (its narrower side: 100 mm on the paper's square)
  is no surface indentation at all, and
  the files it makes fail plausibility later: refused in one line naming ``--fmax``, before
  anything is simulated. :func:`check_depth` solves the normal load ``fmax`` at the plan's
  most exposed locations (nearest the border, where the surface is softest: the deepest of
  all locations on every protocol we measured) in ~0.1 s each, and :func:`check_states_depth`
  checks the states actually simulated (every direction) before they are written;
- deeper than the phantom's thickness (:data:`core.protocol.THICKNESS_M`, 32 mm) the surface
  went through the block. The paper's own protocol does that at edge locations (7.5 N at 100
  and 21 N/m: 30-71 mm), so such states are kept but counted (:func:`beyond`), and simulate's
  closing line says how many.

Depth is the loaded patch's (the tip's) distance below the rest surface (z = 0).
"""

from __future__ import annotations

import numpy as np

from core.errors import BadInput
from sim.msm.msm import MSM, MSMParams
from sim.msm.msm_protocol import Plan
from sim.msm.msm_sampling import contact_masses
from sim.msm.msm_static import StaticSolver, simulate_sequence

CHECK_STEPS = 3          # force steps of the check's static path (large loads need a path)
CHECK_TOL_N = 1e-5       # its tolerance: depths to well below a micrometre
CHECK_LOCATIONS = 4      # the most exposed locations solved
NORMAL = np.array([0.0, 0.0, -1.0])


def exposed(plan: Plan, model: MSM, locations: np.ndarray, count: int = CHECK_LOCATIONS
            ) -> np.ndarray:
    """The ``count`` locations whose loaded mass is nearest the border (then nearest a
    corner): where the surface is softest."""
    xy = model.rest[plan.nodes[locations], :2]
    near = np.minimum(xy, np.array(model.params.footprint) - xy)   # (L, 2): to the nearer edge
    order = np.lexsort((near.max(axis=1), near.min(axis=1)))
    return np.asarray(locations)[order[:count]]


def normal_depths(plan: Plan, params: MSMParams, locations: np.ndarray) -> np.ndarray:
    """The depth (m) of the loaded patch under the normal load ``fmax`` at each location."""
    p = plan.protocol
    model = MSM(params)
    solver = StaticSolver(model, CHECK_TOL_N)
    depths = np.empty(len(locations))
    for i, loc in enumerate(locations):
        contact = contact_masses(model, model.rest[plan.nodes[loc], :2], p.contact_radius)
        solver.reset()
        x = simulate_sequence(model, contact, NORMAL, CHECK_STEPS, p.fmax, CHECK_TOL_N,
                              solver)[-1]
        depths[i] = float((model.rest[contact, 2] - x[contact, 2]).mean())
    return depths


def check_depth(plan: Plan, params: MSMParams, locations: np.ndarray,
                thickness: float) -> float:
    """Refuse a plan whose normal load drives the MSM deeper than its surface is wide, before
    simulating; returns the deepest depth found (m)."""
    where = exposed(plan, MSM(params), locations)
    depths = normal_depths(plan, params, where)
    k = int(depths.argmax())
    _refuse_too_deep(plan, params, float(depths[k]), thickness, f"location {int(where[k])}")
    return float(depths[k])


def check_states_depth(plan: Plan, params: MSMParams, tips: np.ndarray,
                       thickness: float) -> None:
    """Refuse simulated states (tips (S, 3)) deeper than the MSM's surface is wide."""
    deepest = float(-tips[:, 2].min()) if len(tips) else 0.0
    _refuse_too_deep(plan, params, deepest, thickness, "a simulated state")


def beyond(tips: np.ndarray, thickness: float) -> tuple[int, float]:
    """How many states (tips (S, 3)) lie deeper than ``thickness`` (m), and the deepest (m)."""
    depth = -np.asarray(tips, dtype=float)[:, 2]
    return int((depth > thickness).sum()), float(depth.max()) if len(depth) else 0.0


def _refuse_too_deep(plan: Plan, params: MSMParams, depth: float, thickness: float,
                     where: str) -> None:
    wide = min(params.footprint)
    if depth <= wide:
        return
    raise BadInput(None, f"--fmax {plan.protocol.fmax:g} N drives the MSM {depth * 1e3:.0f} "
                         f"mm deep ({where}; springs {params.k_between:g} and "
                         f"{params.k_fixed:g} N/m), deeper than its surface is wide "
                         f"({wide * 1e3:g} mm) and {depth / thickness:.0f} times the "
                         f"phantom's {thickness * 1e3:g} mm thickness: lower --fmax or "
                         "stiffen the springs")

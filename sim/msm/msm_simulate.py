"""The protocol's locations simulated with the fast static path, side by side in processes.

Each location's sequences are solved step after step (:func:`sim.msm.msm_static.simulate_sequence`)
on every mass or, with a lab's layout, sampled at its markers with the loaded patch's centre
as the last point (:mod:`sim.msm.msm_sampling`). The result does not depend on the number of
worker processes.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from core.progress import progress
from sim.msm.msm import MSM, MSMError, MSMParams, unit
from sim.msm.msm_protocol import Plan
from sim.msm.msm_sampling import contact_masses, sample_at
from sim.msm.msm_static import DEFAULT_TOL, StaticSolver, residual, simulate_sequence
from sim.msm.workers import worker_pool


@dataclass
class Simulated:
    """States of a block of locations, in file order, and what they cost."""

    locations: np.ndarray    # (l,) location indices
    points: np.ndarray       # (l * D * (steps + 1), N, 3) float32
    tips: np.ndarray         # (l * D * (steps + 1), 3) float32: the contact patch's centre
    max_residual: float      # N, largest force on any mass of any state (float64 solution)
    stored_residual: float   # N, the same of the states as stored (cast to float32)
    iterations: int
    factorizations: int
    cpu_s: float             # CPU seconds of the solves, summed over worker processes


def _simulate_location(args: tuple) -> tuple[np.ndarray, np.ndarray, float, float, int, int,
                                             float]:
    """One location, all its directions: the states (D, steps + 1, N, 3) float32 (every mass,
    or the layout's points then the tip), the tip (D, steps + 1, 3), the worst residuals of
    the float64 and of the stored float32 states, and solver counts."""
    cpu = time.process_time()
    params, node, directions, steps, fmax, tol, radius, layout = args
    model = MSM(params)
    solver = StaticSolver(model, tol)
    contact = contact_masses(model, model.rest[node, :2], radius)
    sampling = sample_at(model, layout[:, :2]) if layout is not None else None
    n_out = model.N if layout is None else len(layout) + 1
    out = np.empty((len(directions), steps + 1, n_out, 3), dtype=np.float32)
    tips = np.empty((len(directions), steps + 1, 3), dtype=np.float32)
    stored = 0.0
    for d, direction in enumerate(directions):
        states = simulate_sequence(model, contact, direction, steps, fmax, tol, solver)
        if not np.isfinite(states).all():
            raise MSMError(f"non-finite state at mass {node}, direction {d}")
        tips[d] = states[:, contact].mean(axis=1)
        if sampling is None:
            out[d] = states
        else:
            out[d, :, :-1] = layout + np.stack([sampling.displace(x - model.rest)
                                                for x in states])
            out[d, :, -1] = tips[d]
        for t in range(1, steps + 1):
            load = model.load(contact, unit(direction) * fmax * t / steps)
            x = out[d, t].astype(np.float64) if sampling is None else states[t]
            stored = max(stored, residual(model, x, load))
    stats = solver.stats           # max_residual: of every solve, i.e. every float64 state
    return (out, tips, stats.max_residual, stored, stats.iterations, stats.factorizations,
            time.process_time() - cpu)


def simulate_plan(plan: Plan, params: MSMParams,
                  locations: Sequence[int] | np.ndarray | None = None,
                  tol: float = DEFAULT_TOL, workers: int = 1, layout: np.ndarray | None = None
                  ) -> Simulated:
    """Simulate ``locations`` (default: all) of ``plan`` with the fast static path.

    With ``layout`` (P, 3) the states hold the MSM sampled at those rest positions (a lab's
    markers: :mod:`sim.msm.msm_sampling`) and then the tip, not every mass. ``workers``
    processes share the locations; the result does not depend on how many.
    """
    p = plan.protocol
    locs = np.arange(p.locations) if locations is None else np.asarray(locations)
    jobs = [(params, plan.nodes[loc], plan.directions[loc], p.steps, p.fmax, tol,
             p.contact_radius, layout) for loc in locs]
    per_loc = p.directions * (p.steps + 1)
    n_out = params.n * params.grid_rows if layout is None else len(layout) + 1
    points = np.empty((len(locs) * per_loc, n_out, 3), dtype=np.float32)
    tips = np.empty((len(locs) * per_loc, 3), dtype=np.float32)
    worst = stored = cpu = 0.0
    its = facts = 0
    workers = max(1, min(workers, len(jobs)))
    pool = worker_pool(workers) if workers > 1 else None
    try:
        results = pool.imap(_simulate_location, jobs) if pool else map(_simulate_location, jobs)
        with progress(results, "simulating MSM locations", length=len(jobs)) as bar:
            for k, (states, tip, w, s, i, f, c) in enumerate(bar):
                points[k * per_loc:(k + 1) * per_loc] = states.reshape(per_loc, -1, 3)
                tips[k * per_loc:(k + 1) * per_loc] = tip.reshape(per_loc, 3)
                worst, stored = max(worst, w), max(stored, s)
                its, facts, cpu = its + i, facts + f, cpu + c
    finally:
        if pool:
            pool.terminate()
            pool.join()
    return Simulated(locs, points, tips, worst, stored, its, facts, cpu)

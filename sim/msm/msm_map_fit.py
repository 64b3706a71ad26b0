"""A stiffness map fitted to measured states: one factor per region, on top of the uniform fit.

``fit-msm --map`` first fits the uniform constants (:mod:`sim.msm.msm_fit`), then a factor
``f_r = exp(theta_r)`` per region of a grid over the footprint (:mod:`sim.msm.msm_regions`;
by default the finest grid whose every region holds a press place in its middle, since a
region is told apart only by the presses on it) minimising

    S(theta) = |r(theta)|^2 / |r(0)|^2 + w |theta|^2

where ``r`` stacks every measured point's coordinate error (model minus measurement, every
loaded state of every press), the tip's weighted to count as much as the press's markers
together (how deep the tip sinks under the press's force is where a region's stiffness shows;
the markers' errors are mostly the surface model's shape, the same for every factor), and ``w``
shrinks the map toward the uniform fit. The search is
Gauss-Newton on ``theta`` with the exact derivatives of the equilibria
(:mod:`sim.msm.msm_sensitivity`), halving a step that does not lower ``S``.

**The weight is chosen by held-out presses**, at every step: the presses are cut into
:data:`VALIDATION_GROUPS` groups, each holding out at most one press of a place in turn (a
place pressed once is held out whole; a place is the states file's location id, one rule for
every reader, :mod:`data_schema.places`); for each weight of :data:`WEIGHTS` and each group,
the step is taken on the other groups' presses alone and scored on the group's (through the
fit's linearisation at the current map), and the weight whose held-out error is lowest is the
step's. The last step's table is reported.

**The uncertainty** of each factor is the curvature's, with the presses as the independent
draws: ``cov(theta) = H^-1 (sum_p g_p g_p^T) H^-1`` at the final map, ``H = J^T J + w |r(0)|^2
I`` and ``g_p`` press p's gradient ``J_p^T r_p`` (the points of one press err alike, so
counting them as independent would claim far more certainty than the presses give).

**Regions the presses cannot tell.** A region is informed by the presses whose tip rests
within :data:`REGION_REACH_M` of it; one with none is held at the uniform fit (factor 1, no
uncertainty), and where fewer than two regions are informed the whole map is uniform. Either
is said in one line (:attr:`MapResult.note`). The reach is how near a press must be for the
depth its tip sinks to tell the region's springs (the masses sharing its load and their
neighbours, a few millimetres on the paper's grid); it is not eval's
:data:`train.evaluation.lump.LUMP_REACH_M` (10 mm), which says which presses dent the surface
over a lump, as L_d measures the whole surface: a wider question.
"""

from __future__ import annotations

import math
import multiprocessing.pool
from dataclasses import dataclass, replace

import numpy as np

from data_schema.places import place_ids
from sim.msm.msm import MSM, MSMParams
from sim.msm.msm_fit import at_points, distances, grid_states
from sim.msm.msm_measured import MeasuredSequence
from sim.msm.msm_regions import finest_grid, region_bounds, region_centres
from sim.msm.msm_sensitivity import mass_regions, state_derivatives
from sim.msm.workers import worker_pool

REGION_REACH_M = 0.005     # m: a press whose tip rests this close to a region informs it
WEIGHTS = (0.0, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 0.1, 0.3, 1.0)   # shrinkage tried
VALIDATION_GROUPS = 3      # presses held out in turn to choose the weight
MAX_STEPS = 8              # Gauss-Newton steps
STEP_TOL = 1e-3            # stop when no log factor moves more than this
LOG_FACTOR_LIMIT = math.log(20.0)   # a factor stays within [1/20, 20]


@dataclass(frozen=True)
class MapResult:
    """The fitted map: ``factors[i][j]`` of the region of y band i and x band j."""

    shape: tuple[int, int]
    factors: list[list[float]]
    sd: list[list[float | None]]          # each factor's standard deviation; None: held at 1
    informed_by: list[list[list[int]]]    # per region, the sequences (presses) informing it
    places: int                           # distinct press places
    weight: float                         # the shrinkage the held-out presses chose
    validation: list[dict]                # per weight tried, the held-out RMS error (m)
    mean_distance_m: float                # at the map
    uniform_distance_m: float             # at the uniform fit
    steps: int
    note: str = ""                        # one line where regions could not be told apart
    stiffest: dict | None = None          # the stiffest fitted region: its "region" (row,
                                          # column), "centre_mm" (x, y), "factor", "sd", and
                                          # "peak_mm" (x, y) among its neighbours


def tip_xy(seq: MeasuredSequence) -> np.ndarray:
    """Where a press's tip rests on the footprint (2,), m."""
    return seq.rest[seq.is_tip][0, :2]


def informing(sequences: list[MeasuredSequence], footprint: tuple[float, float],
              shape: tuple[int, int]) -> list[list[list[int]]]:
    """Per region, the sequence ids whose tip rests within :data:`REGION_REACH_M` of it."""
    out = []
    for i in range(shape[0]):
        row = []
        for j in range(shape[1]):
            x0, x1, y0, y1 = region_bounds(footprint, shape, i, j)
            row.append([s.sequence for s in sequences
                        if x0 - REGION_REACH_M <= tip_xy(s)[0] <= x1 + REGION_REACH_M
                        and y0 - REGION_REACH_M <= tip_xy(s)[1] <= y1 + REGION_REACH_M])
        out.append(row)
    return out


def press_places(sequences: list[MeasuredSequence]) -> np.ndarray:
    """Each sequence's press place (K,), numbered in the order first met: its location id in
    the states file (:func:`data_schema.places.place_ids`; each press its own place where the
    sequences carry none)."""
    locations = [s.location for s in sequences]
    known = None if None in locations else np.asarray(locations)
    return place_ids(known, len(sequences))


def place_centres(sequences: list[MeasuredSequence]) -> np.ndarray:
    """The distinct press places (K, 2), m: the mean tip of each place's presses."""
    ids = press_places(sequences)
    tips = np.array([tip_xy(s) for s in sequences]).reshape(-1, 2)
    return np.array([tips[ids == i].mean(axis=0) for i in range(ids.max(initial=-1) + 1)]
                    ).reshape(-1, 2)


def fit_map(sequences: list[MeasuredSequence], params: MSMParams,
            shape: tuple[int, int] | None = None, seed: int = 0, workers: int = 1
            ) -> MapResult:
    """The map over ``shape`` regions (None: the finest grid the press places cover,
    :func:`sim.msm.msm_regions.finest_grid`) on top of ``params``' uniform constants (see the
    module docstring), the sequences shared among ``workers`` processes."""
    centres = place_centres(sequences)
    shape = shape or finest_grid(centres, params.footprint)
    informed = informing(sequences, params.footprint, shape)
    free = np.flatnonzero([bool(s) for row in informed for s in row])
    places, uniform = len(centres), distances(
        [at_points(params, s, grid_states(params, s)) for s in sequences], sequences).pooled
    if len(free) < 2:
        note = (f"the presses cannot tell regions apart: {places} distinct place(s), "
                f"{len(free)} of {shape[0]}x{shape[1]} region(s) with a press within "
                f"{REGION_REACH_M * 1e3:g} mm; the map is uniform")
        ones = [[1.0] * shape[1] for _ in range(shape[0])]
        return MapResult(shape, ones, [[None] * shape[1] for _ in range(shape[0])], informed,
                         places, 0.0, [], uniform, uniform, 0, note)
    pool = worker_pool(min(workers, len(sequences))) if workers > 1 else None
    try:
        return _search(sequences, params, shape, free, informed, places, uniform, seed, pool)
    finally:
        if pool:
            pool.terminate()
            pool.join()


def with_map(params: MSMParams, shape: tuple[int, int], free: np.ndarray, theta: np.ndarray
             ) -> MSMParams:
    """``params`` with the factors ``exp(theta)`` on the ``free`` regions, 1 elsewhere."""
    table = np.ones(shape[0] * shape[1])
    table[free] = np.exp(theta)
    return replace(params, stiffness_map=tuple(tuple(row) for row in
                                               table.reshape(shape).tolist()))


def _search(sequences: list[MeasuredSequence], params: MSMParams, shape: tuple[int, int],
            free: np.ndarray, informed: list, places: int, uniform: float, seed: int,
            pool: multiprocessing.pool.Pool | None) -> MapResult:
    """Gauss-Newton with the weight chosen by held-out presses at each step."""
    groups = _groups(sequences, seed)
    theta = np.zeros(len(free))
    ev = _evaluate(params, shape, free, theta, sequences, pool)
    scale = float(ev.r @ ev.r)
    steps, weight, table = 0, 0.0, list[dict]()
    while steps < MAX_STEPS:
        steps += 1
        weight, table = _choose_weight(ev, theta, groups, scale)
        delta = _step(ev.jac, ev.r, theta, weight, scale)
        before = float(ev.r @ ev.r) / scale + weight * float(theta @ theta)
        for _ in range(5):
            new = np.clip(theta + delta, -LOG_FACTOR_LIMIT, LOG_FACTOR_LIMIT)
            trial = _evaluate(params, shape, free, new, sequences, pool)
            if float(trial.r @ trial.r) / scale + weight * float(new @ new) <= before:
                break
            delta = delta / 2
        theta, ev = new, trial
        if np.abs(delta).max() < STEP_TOL:
            break
    found = _result(ev, theta, weight, scale, table, shape, free, informed, places, uniform,
                    steps, sequences)
    return replace(found, stiffest=stiffest_region(found, params.footprint))


@dataclass(frozen=True)
class _Evaluation:
    """Every coordinate error (m,) of the presses at one map, its derivatives (m, p), the
    rows of each press, and the predicted points."""

    r: np.ndarray
    jac: np.ndarray
    press_rows: np.ndarray          # (m,) the press (index into the sequences) of each row
    predicted: list[np.ndarray]


def _evaluate(params: MSMParams, shape: tuple[int, int], free: np.ndarray, theta: np.ndarray,
              sequences: list[MeasuredSequence], pool: multiprocessing.pool.Pool | None
              ) -> _Evaluation:
    jobs = [(with_map(params, shape, free, theta), shape, free, s) for s in sequences]
    parts = pool.map(_press, jobs) if pool else list(map(_press, jobs))
    rows = np.concatenate([np.full(len(p[0]), k) for k, p in enumerate(parts)])
    return _Evaluation(np.concatenate([p[0] for p in parts]),
                       np.concatenate([p[1] for p in parts]), rows, [p[2] for p in parts])


def _press(job: tuple[MSMParams, tuple[int, int], np.ndarray, MeasuredSequence]
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One press: its finite coordinate errors (k,), their derivatives (k, p), the points."""
    params, shape, free, seq = job
    model = MSM(params)
    states = grid_states(params, seq)
    regions = mass_regions(model, shape)
    count = shape[0] * shape[1]
    moved = np.stack([state_derivatives(model, x, regions, count)[free] for x in states])
    predicted = at_points(params, seq, states)                       # (T, P, 3)
    t, p = moved.shape[:2]
    dpoints = at_points(params, seq, model.rest + moved.reshape(t * p, model.N, 3)) \
        - seq.rest                                                   # (T p, P, 3)
    dpoints = dpoints.reshape(t, p, *predicted.shape[1:]).transpose(0, 2, 3, 1)
    error = predicted - seq.points
    weight = np.where(seq.is_tip, math.sqrt(max(int((~seq.is_tip).sum()), 1)), 1.0)
    error, dpoints = error * weight[:, None], dpoints * weight[:, None, None]
    keep = np.isfinite(error)
    return error[keep], dpoints[keep], predicted


def _groups(sequences: list[MeasuredSequence], seed: int) -> list[np.ndarray]:
    """The presses (indices) of each held-out group: the presses of each place in a seeded
    order, the k-th of every place in group k mod :data:`VALIDATION_GROUPS`, so a group
    holds out presses at places the others still press (where a place has more than one)."""
    ids = press_places(sequences)
    seen = np.zeros(ids.max(initial=-1) + 1, dtype=int)
    group = np.empty(len(sequences), dtype=int)
    for k in np.random.default_rng(seed).permutation(len(sequences)):
        group[k] = seen[ids[k]] % VALIDATION_GROUPS
        seen[ids[k]] += 1
    return [np.flatnonzero(group == g) for g in range(VALIDATION_GROUPS) if (group == g).any()]


def _step(jac: np.ndarray, r: np.ndarray, theta: np.ndarray, weight: float, scale: float
          ) -> np.ndarray:
    """The Gauss-Newton step of ``S`` from ``theta`` (least squares where singular)."""
    a = jac.T @ jac / scale + weight * np.eye(len(theta))
    b = jac.T @ r / scale + weight * theta
    return -np.linalg.lstsq(a, b, rcond=None)[0]


def _choose_weight(ev: _Evaluation, theta: np.ndarray, groups: list[np.ndarray], scale: float
                   ) -> tuple[float, list[dict]]:
    """The weight of :data:`WEIGHTS` whose steps, taken without each group's presses, best
    predict those presses; with the held-out RMS error (m) of every weight."""
    table = []
    for weight in WEIGHTS:
        total = 0.0
        for group in groups:
            out = np.isin(ev.press_rows, group)
            delta = _step(ev.jac[~out], ev.r[~out], theta, weight, scale)
            res = ev.r[out] + ev.jac[out] @ delta
            total += float(res @ res)
        table.append({"weight": weight, "held_out_rms_m": math.sqrt(total / len(ev.r))})
    best = min(table, key=lambda row: row["held_out_rms_m"])
    return best["weight"], table


def stiffest_region(found: MapResult, footprint: tuple[float, float]) -> dict | None:
    """The fitted region (not held at 1) of the largest factor: where the map puts a lump.
    Its ``peak_mm`` is the centre of mass of that region and its fitted neighbours, each
    weighted by its factor above the map's median (a peak between regions is shared by them:
    a lump between four places stiffens all four)."""
    fitted = np.array([[sd is not None for sd in row] for row in found.sd])
    if not fitted.any():
        return None
    factors = np.asarray(found.factors)
    i, j = np.unravel_index(np.argmax(np.where(fitted, factors, -np.inf)), factors.shape)
    centres = region_centres(footprint, found.shape) * 1e3
    near = np.zeros_like(fitted)
    near[max(i - 1, 0):i + 2, max(j - 1, 0):j + 2] = True
    weight = np.where(near & fitted, np.clip(factors - np.median(factors[fitted]), 0, None), 0)
    peak = (weight[..., None] * centres).sum((0, 1)) / weight.sum() if weight.sum() > 0 \
        else centres[i, j]
    return {"region": [int(i), int(j)], "centre_mm": [round(float(v), 3) for v in centres[i, j]],
            "peak_mm": [round(float(v), 3) for v in peak], "factor": float(factors[i, j]),
            "sd": found.sd[i][j]}


def _press_covariance(ev: _Evaluation, ridge: float) -> np.ndarray:
    """``H^-1 (sum_p g_p g_p^T) H^-1 p / (p - 1)``: the curvature ``H = J^T J + ridge I``
    around the spread of each press's gradient ``g_p = J_p^T r_p`` (a press's points err
    alike, so the presses, not the points, are the independent draws)."""
    inverse = np.linalg.pinv(ev.jac.T @ ev.jac + ridge * np.eye(ev.jac.shape[1]))
    presses = np.unique(ev.press_rows)
    grads = np.stack([ev.jac[ev.press_rows == p].T @ ev.r[ev.press_rows == p] for p in presses])
    spread = grads.T @ grads * len(presses) / max(len(presses) - 1, 1)
    return inverse @ spread @ inverse


def _result(ev: _Evaluation, theta: np.ndarray, weight: float, scale: float, table: list,
            shape: tuple[int, int], free: np.ndarray, informed: list, places: int,
            uniform: float, steps: int, sequences: list[MeasuredSequence]) -> MapResult:
    """The map with each factor's curvature uncertainty, and the note on held regions."""
    cov = _press_covariance(ev, weight * scale)
    factors = np.ones(shape[0] * shape[1])
    sd: list[float | None] = [None] * len(factors)
    factors[free] = np.exp(theta)
    for k, region in enumerate(free):
        sd[region] = float(factors[region] * math.sqrt(max(cov[k, k], 0.0)))
    held = [f"r{k // shape[1]}c{k % shape[1]}" for k in range(len(factors)) if k not in free]
    notes = [f"region(s) {', '.join(held)} of {shape[0]}x{shape[1]} have no press within "
             f"{REGION_REACH_M * 1e3:g} mm: held at the uniform fit (factor 1)"] if held else []
    if weight == WEIGHTS[-1]:
        notes.append(f"the held-out presses chose the strongest shrinkage tried ({weight:g}): "
                     "they are predicted no better by a map than by a flatter one")
    note = "; ".join(notes)
    return MapResult(shape, factors.reshape(shape).tolist(),
                     [sd[i * shape[1]:(i + 1) * shape[1]] for i in range(shape[0])], informed,
                     places, weight, table, distances(ev.predicted, sequences).pooled,
                     uniform, steps, note)

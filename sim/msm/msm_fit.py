"""Fit the MSM's spring constants to measured states, as the paper did.

The paper chose (k_between, k_fixed) to minimise the mean distance between measured surface
points and the MSM's static response to the measured loading (it found 100 and 21 N/m for its
phantom). The measured sequences are placed on the grid by :mod:`sim.msm.msm_measured`.

The model response of a sequence is solved step after step by the fast static path. The search
(Nelder-Mead on log k, bounded to [K_MIN, K_MAX] N/m) starts at ``start``, which must settle
(else :class:`BadInput`); a trial the solver cannot settle within ``FIT_MAX_ITER`` iterations
of one solve counts as no optimum. Beside the fitted distance it reports the start's, a still
surface's (nothing moves, the tip neither) and "nothing moves" with the tip at its measured
end, pooled and per sequence, and names any constant that ended on a bound.
"""

from __future__ import annotations

import math
import multiprocessing.pool
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import minimize

from core.errors import BadInput
from sim.msm import paper
from sim.msm.msm import MSM, MSMError, MSMParams
from sim.msm.msm_grid import describe
from sim.msm.msm_measured import MeasuredSequence
from sim.msm.msm_static import StaticSolver, solve_path
from sim.msm.workers import worker_pool

FIT_TOL = 1e-7            # N, static tolerance inside the fit (well below the fit's resolution)
FIT_MAX_ITER = 200        # iterations of one solve before a trial counts as unsettled
K_MIN, K_MAX = 1.0, 1e5   # N/m: the physical range searched (and reported when reached)


@dataclass(frozen=True)
class Distances:
    """Mean point distance (m) of one prediction, pooled and per sequence."""

    pooled: float
    per_sequence: list[float]


@dataclass(frozen=True)
class FitResult:
    k_between: float
    k_fixed: float
    mean_distance_m: float       # at the fitted constants
    start_distance_m: float      # at the start constants
    still_distance_m: float      # a surface that does not move, the tip neither
    nothing_moves_distance_m: float   # the surface still, the tip at its measured end
    evaluations: int
    sequences: int
    states: int
    contact_radius_m: float = 0.0
    at_bound: list[str] = field(default_factory=list)
    per_sequence: list[dict] = field(default_factory=list)
    grid: str = ""               # the surface fitted on, e.g. "150 x 80 mm of 48 x 26 masses"


def grid_states(params: MSMParams, seq: MeasuredSequence, tol: float = FIT_TOL,
                max_iter: int = FIT_MAX_ITER) -> np.ndarray:
    """The MSM's equilibria (T, N, 3) under a sequence's loads, every mass.

    Raises :class:`MSMError` where a solve does not settle within ``max_iter`` iterations.
    """
    model = MSM(params)
    loads = (model.load(seq.contact, f) for f in seq.forces)
    return np.stack(list(solve_path(StaticSolver(model, tol, max_iter), loads)))


def at_points(params: MSMParams, seq: MeasuredSequence, states: np.ndarray) -> np.ndarray:
    """Grid states (T, N, 3) seen at a sequence's measured points (T, P, 3)."""
    disp = states - MSM(params).rest
    moved = np.stack([seq.sampling.displace(d) for d in disp])
    moved[:, seq.is_tip] = disp[:, seq.contact].mean(axis=1, keepdims=True)
    return seq.rest + moved


def model_states(params: MSMParams, seq: MeasuredSequence, tol: float = FIT_TOL,
                 max_iter: int = FIT_MAX_ITER) -> np.ndarray:
    """The MSM's prediction of a sequence's measured points (T, P, 3)."""
    return at_points(params, seq, grid_states(params, seq, tol, max_iter))


def distances(predicted: list[np.ndarray], sequences: list[MeasuredSequence]) -> Distances:
    """Mean distance (m) between predicted and measured points over every finite pair."""
    sums, counts = [], []
    for pred, seq in zip(predicted, sequences, strict=True):
        d = np.linalg.norm(pred - seq.points, axis=-1)
        d = d[np.isfinite(d)]                   # a point missing at rest or in that state
        sums.append(float(d.sum()))
        counts.append(len(d))
    if sum(counts) == 0:
        raise BadInput(None, "no finite measured point to compare with the MSM")
    return Distances(sum(sums) / sum(counts), [s / max(c, 1) for s, c in zip(sums, counts,
                                                                             strict=True)])


def _states_of(job: tuple[MSMParams, MeasuredSequence]) -> np.ndarray:
    return model_states(*job)


def predict_all(params: MSMParams, sequences: list[MeasuredSequence],
                pool: multiprocessing.pool.Pool | None = None) -> list[np.ndarray]:
    """:func:`model_states` of every sequence, shared among ``pool``'s processes if given."""
    jobs = [(params, s) for s in sequences]
    return pool.map(_states_of, jobs) if pool else list(map(_states_of, jobs))


def mean_distance(params: MSMParams, sequences: list[MeasuredSequence],
                  pool: multiprocessing.pool.Pool | None = None) -> float:
    """Mean distance (m) over the loaded states' points between measurement and MSM."""
    return distances(predict_all(params, sequences, pool), sequences).pooled


def still(sequences: list[MeasuredSequence], tip_moves: bool) -> Distances:
    """Distances of a surface that does not move: the tip too, or the tip at its measured
    position (what the network's condition C gives it: the "nothing moves" reference)."""
    predicted = []
    for seq in sequences:
        pred = np.broadcast_to(seq.rest, seq.points.shape).copy()
        if tip_moves:
            pred[:, seq.is_tip] = seq.points[:, seq.is_tip]
        predicted.append(pred)
    return distances(predicted, sequences)


def fit_msm(sequences: list[MeasuredSequence], params: MSMParams,
            start: tuple[float, float] = (paper.K_BETWEEN, paper.K_FIXED),
            rel_tol: float = 1e-2,
            workers: int = 1) -> FitResult:
    """Spring constants (k_between, k_fixed) in [K_MIN, K_MAX] minimising the mean distance,
    to ``rel_tol`` relative precision, the sequences shared among ``workers`` processes.

    The start is evaluated first: where the MSM cannot settle there, or the distance is not
    finite, :class:`BadInput` says so at once (a search from there would only meet failing
    trials). A result that is not finite is refused the same way.
    """
    pool = worker_pool(min(workers, len(sequences))) if workers > 1 else None
    try:
        return _search(sequences, params, start, rel_tol, pool)
    finally:
        if pool:
            pool.terminate()
            pool.join()


def _search(sequences: list[MeasuredSequence], params: MSMParams, start: tuple[float, float],
            rel_tol: float, pool: multiprocessing.pool.Pool | None) -> FitResult:
    """Nelder-Mead on log k from ``start`` (see :func:`fit_msm`)."""
    if not all(map(math.isfinite, start)) or not all(K_MIN <= k <= K_MAX for k in start):
        raise BadInput("--start", f"constants must lie in [{K_MIN:g}, {K_MAX:g}] N/m, "
                                  f"got {start}")
    at_start = f"at --start {start[0]:g} {start[1]:g} N/m"
    known: dict[bytes, float] = {}

    def objective(log_k: np.ndarray) -> float:
        key = np.asarray(log_k, dtype=float).tobytes()
        if key not in known:
            kb, kf = np.exp(log_k)
            try:
                known[key] = mean_distance(replace(params, k_between=float(kb),
                                                   k_fixed=float(kf)), sequences, pool)
            except MSMError:
                known[key] = math.inf        # a trial the solver cannot settle is no optimum
        return known[key]

    x0 = np.log(np.asarray(start, dtype=float))
    f0 = objective(x0)
    if not math.isfinite(f0):
        raise BadInput("--start", f"the MSM cannot settle {at_start} (or the distance is not "
                                  "finite); start from constants nearer the expected ones")
    lo, hi = math.log(K_MIN), math.log(K_MAX)
    simplex = np.clip(np.array([x0, x0 + [0.4, 0.0], x0 + [0.0, 0.4]]), lo, hi)
    res = minimize(objective, x0, method="Nelder-Mead", bounds=[(lo, hi), (lo, hi)],
                   options={"initial_simplex": simplex, "xatol": rel_tol, "fatol": 1e-7,
                            "maxfev": 200})
    if not math.isfinite(res.fun):
        raise BadInput("--start", f"the fit found no constants where the MSM settles "
                                  f"(best mean distance {res.fun}) starting {at_start}")
    kb, kf = (float(v) for v in np.exp(res.x))
    return _result(params, sequences, (kb, kf), start, len(known), pool)


def _result(params: MSMParams, sequences: list[MeasuredSequence], fitted: tuple[float, float],
            start: tuple[float, float], evaluations: int,
            pool: multiprocessing.pool.Pool | None) -> FitResult:
    """The fit's record: distances pooled and per sequence, and constants on a bound."""
    def at(k: tuple[float, float]) -> Distances:
        p = replace(params, k_between=k[0], k_fixed=k[1])
        return distances(predict_all(p, sequences, pool), sequences)

    fit, first, none, tip_only = at(fitted), at(start), still(sequences, False), \
        still(sequences, True)
    per = [{"sequence": s.sequence, "fitted_m": a, "start_m": b, "still_m": c,
            "nothing_moves_m": d}
           for s, a, b, c, d in zip(sequences, fit.per_sequence, first.per_sequence,
                                    none.per_sequence, tip_only.per_sequence, strict=True)]
    bound = [f"{name} at its {'lower' if k <= K_MIN * 1.01 else 'upper'} bound {k:.3g} N/m"
             for name, k in zip(("k_between", "k_fixed"), fitted, strict=True)
             if k <= K_MIN * 1.01 or k >= K_MAX / 1.01]
    return FitResult(fitted[0], fitted[1], fit.pooled, first.pooled, none.pooled,
                     tip_only.pooled, evaluations, len(sequences),
                     sum(len(s.forces) for s in sequences), sequences[0].contact_radius, bound,
                     per, describe(params))

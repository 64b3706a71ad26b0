"""Fit the MSM's spring constants to measured states, as the paper did.

The paper chose (k_between, k_fixed) to minimise the mean distance between measured surface
points and the MSM's static response to the measured loading (it found 100 and 21 N/m for its
phantom). A ``phantom.states`` 2.0 file is in the phantom frame, which is the MSM grid's frame
(footprint ``[0, size]^2``, rest surface at z = 0, +z out of the surface), so measured points
are placed on the grid where they are, with no frame of their own to guess:

- each point follows the bilinear blend of the four masses around its rest (x, y)
  (:mod:`sim.msm_sampling`): MSM states (points = the masses) land on their own mass, lab
  markers between masses;
- the tip (the point at the tip's rest position: the lab's 26th point, the MSM's loaded mass)
  is the contact patch: the masses within ``contact_radius`` of it (at least the nearest, the
  paper's n_n = 1) share the load and the tip follows their mean;
- the load of a state is ``force_vector`` where the file has it (MSM), else the measured force
  magnitude along the tip's overall motion in that press (lab: the indenter pushes where it
  goes; never a guessed sign).

The model response of a sequence is solved step after step by the fast static path. The search
(Nelder-Mead on log k, bounded to [K_MIN, K_MAX] N/m) starts at ``start``, which must settle
(else :class:`BadInput`); a trial the solver cannot settle within ``FIT_MAX_ITER`` iterations
of one solve counts as no optimum. Beside the fitted distance it reports the start's, a still
surface's (nothing moves, the tip neither) and "nothing moves" with the tip at its measured
end, pooled and per sequence, and names any constant that ended on a bound.
"""

from __future__ import annotations

import json
import math
import multiprocessing.pool
from dataclasses import dataclass, field, replace
from pathlib import Path

import h5py
import numpy as np
from scipy.optimize import minimize

from core.errors import BadInput
from data_schema.hdf5 import attr_text
from data_schema.states import validate_states
from sim.msm import MSM, MSMError, MSMParams
from sim.msm_sampling import Sampling, contact_masses, sample_at
from sim.msm_static import StaticSolver, solve_path
from sim.workers import worker_pool

FIT_TOL = 1e-7            # N, static tolerance inside the fit (well below the fit's resolution)
FIT_MAX_ITER = 200        # iterations of one solve before a trial counts as unsettled
TIP_MATCH = 1e-6          # m: a rest point this close to the tip's rest is the tip
K_MIN, K_MAX = 1.0, 1e5   # N/m: the physical range searched (and reported when reached)


@dataclass(frozen=True)
class MeasuredSequence:
    """One sequence in the grid (= phantom) frame: rest and loaded states of its points."""

    sequence: int            # its id in the file
    contact_radius: float    # m: the load is shared by the masses this close to the tip
    contact: np.ndarray      # (M,) masses sharing the load
    sampling: Sampling       # where each point sits on the grid
    is_tip: np.ndarray       # (P,) bool: the point that follows the contact patch
    rest: np.ndarray         # (P, 3) measured rest positions (NaN: missing)
    forces: np.ndarray       # (T, 3) load of each loaded state, in order
    points: np.ndarray       # (T, P, 3) measured positions of each loaded state


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


def read_measured(path: str | Path, params: MSMParams | None = None,
                  max_sequences: int | None = None, seed: int = 0,
                  contact_radius: float | None = None, only: np.ndarray | None = None
                  ) -> tuple[list[MeasuredSequence], MSMParams]:
    """The sequences of a states file on the MSM grid, and the grid parameters to fit with.

    For an MSM file the grid (n, size, ...) and contact radius are the ones it was made with.
    ``only`` keeps those sequence ids (the training presses of a fold); ``max_sequences``
    then keeps that many of them, drawn with ``seed``.
    """
    path = Path(path)
    validate_states(path)
    with h5py.File(path, "r") as f:
        source = attr_text(f.attrs["source"])
        file_params = f.attrs.get("msm_params")
        protocol = json.loads(attr_text(f.attrs.get("protocol", "{}")) or "{}")
        seq, step = f["states/sequence"][()], f["states/step"][()]
        force = f["states/force"][()].astype(float)
        fvec = f["states/force_vector"][()].astype(float) if "states/force_vector" in f else None
        tip = f["states/tip"][()].astype(float)
        ids = _chosen(np.unique(seq), only, max_sequences, seed, path)
        rows = {int(s): np.flatnonzero(seq == s) for s in ids}
        wanted = np.sort(np.concatenate(list(rows.values())))
        points = dict(zip(wanted.tolist(), f["states/points"][wanted].astype(float),
                          strict=True))
    if params is None and source == "msm" and file_params is not None:
        try:
            params = MSMParams(**json.loads(attr_text(file_params)))
        except (TypeError, ValueError) as e:
            raise BadInput(path, f"unreadable msm_params attribute ({e})") from None
    if contact_radius is None:
        contact_radius = float(protocol.get("contact_radius", 0.0)) if source == "msm" else 0.0
    model = MSM(params or MSMParams())
    sequences = []
    for s, r in rows.items():
        r = r[np.argsort(step[r], kind="stable")]
        if step[r[0]] != 0:
            raise BadInput(path, f"sequence {s} has no rest state (step 0)")
        if len(r) >= 2:
            loads = fvec[r[1:]] if fvec is not None else _loads_along_tip(force[r[1:]], tip[r])
            sequences.append(_measured(path, model, s, tip[r[0]],
                                       [points[int(i)] for i in r], loads, contact_radius))
    if not sequences:
        raise BadInput(path, "no sequence with a rest state and a loaded state to fit")
    return sequences, model.params


def _chosen(ids: np.ndarray, only: np.ndarray | None, most: int | None, seed: int,
            path: Path) -> np.ndarray:
    """The sequence ids to fit: those in ``only``, at most ``most`` of them (seeded)."""
    if only is not None:
        missing = np.setdiff1d(only, ids)
        if len(missing):
            raise BadInput(path, f"has no sequence {int(missing[0])} (asked for by the fold)")
        ids = np.intersect1d(ids, only)
    if most is not None and len(ids) > most:
        ids = np.sort(np.random.default_rng(seed).choice(ids, most, replace=False))
    return ids


def _loads_along_tip(force: np.ndarray, tips: np.ndarray) -> np.ndarray:
    """Lab loads (T, 3): each force magnitude along the tip's motion from rest to its last
    state (the indenter pushes where it goes); straight down where the tip did not move."""
    motion = tips[-1] - tips[0]
    length = np.linalg.norm(motion)
    direction = motion / length if length > 1e-6 else np.array([0.0, 0.0, -1.0])
    return force[:, None] * direction


def _measured(path: Path, model: MSM, sequence: int, tip_rest: np.ndarray,
              states: list[np.ndarray], loads: np.ndarray, contact_radius: float
              ) -> MeasuredSequence:
    """One sequence placed on the grid."""
    rest = states[0]
    if not (np.isfinite(tip_rest).all() and np.isfinite(loads).all()):
        raise BadInput(path, f"sequence {sequence}: the tip at rest or a load is not finite")
    is_tip = np.linalg.norm(rest - tip_rest, axis=1) < TIP_MATCH
    return MeasuredSequence(sequence, contact_radius,
                            contact_masses(model, tip_rest[:2], contact_radius),
                            sample_at(model, rest[:, :2]), is_tip, rest, loads,
                            np.stack(states[1:]))


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
            start: tuple[float, float] = (100.0, 21.0), rel_tol: float = 1e-2,
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
                     per)

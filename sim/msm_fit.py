"""Fit the MSM's spring constants to measured states, as the paper did.

The paper chose (k_between, k_fixed) to minimise the mean distance between measured surface
points and the MSM's static response to the measured loading (it found 100 and 21 N/m). Here:

- MSM-produced states (``source = "msm"``, points = the grid's masses): each point is its mass,
  the loaded mass is the one at the tip's rest position, the load is ``force_vector``.
- Lab states (e.g. 25 markers + tip): the MSM grid is laid on the plane of the rest surface
  points (step 0 of the first sequence, the tip left out): centred on their centroid, +z the
  side the force pushes from, x along the rows of the marker layout: the directions from each
  marker to its nearest neighbour, folded modulo 90 degrees (their mean of 4 x angle), give
  the phantom's yaw in that plane, taken within 45 degrees of the lab's x axis. (Not the
  principal axis of the points: a square layout such as 5 x 5 markers has no preferred one.)
  Without a grid-like layout (nearest-neighbour directions that do not agree) x is the lab's
  x axis projected on the plane. Each measured point follows the mass nearest its rest
  position, the loaded mass is the one nearest the tip, the load is ``force_vector`` (rotated
  into the grid frame) or, without it, ``force`` along -z.

The model response of a sequence is solved step after step by the fast static path, each from
the previous one; Nelder-Mead searches log(k) from ``start``. The start must settle (else
:class:`BadInput`); a trial the solver cannot settle within ``FIT_MAX_ITER`` iterations of one
solve counts as no optimum, which bounds its cost to about a second.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

import h5py
import numpy as np
from scipy.optimize import minimize

from core.errors import BadInput
from data_schema.hdf5 import attr_text
from data_schema.states import validate_states
from sim.blas_threads import blas_threads
from sim.msm import MSM, MSMError, MSMParams
from sim.msm_static import StaticSolver

FIT_TOL = 1e-7            # N, static tolerance inside the fit (well below the fit's resolution)
FIT_MAX_ITER = 200        # iterations of one solve before a trial counts as unsettled
TIP_RADIUS = 1e-3         # m: a rest point this close to the tip is the tip, not the surface
GRID_AGREEMENT = 0.5      # least resultant of the folded neighbour directions to trust them


@dataclass(frozen=True)
class MeasuredSequence:
    """One sequence in the MSM grid frame: rest and loaded states of its points."""

    node: int                # loaded mass
    masses: np.ndarray       # (P,) mass followed by each measured point
    rest: np.ndarray         # (P, 3) measured rest positions
    forces: np.ndarray       # (T, 3) load of each loaded state, in order
    points: np.ndarray       # (T, P, 3) measured positions of each loaded state


@dataclass(frozen=True)
class FitResult:
    k_between: float
    k_fixed: float
    mean_distance_m: float       # at the fitted constants
    start_distance_m: float      # at the start constants
    evaluations: int
    sequences: int
    states: int


def read_measured(path: str | Path, params: MSMParams | None = None,
                  max_sequences: int | None = None, seed: int = 0
                  ) -> tuple[list[MeasuredSequence], MSMParams]:
    """The sequences of a states file in the MSM frame, and the grid parameters to fit with.

    For an MSM file the grid (n, size, ...) is the one it was made with; ``max_sequences``
    keeps that many sequences, drawn with ``seed``.
    """
    path = Path(path)
    validate_states(path)
    with h5py.File(path, "r") as f:
        source = attr_text(f.attrs["source"])
        file_params = f.attrs.get("msm_params")
        seq = f["states/sequence"][()]
        step = f["states/step"][()]
        points_ds = f["states/points"]
        force = f["states/force"][()].astype(float)
        fvec = f["states/force_vector"][()].astype(float) if "states/force_vector" in f else None
        tip = f["states/tip"][()].astype(float)
        ids = np.unique(seq)
        if max_sequences is not None and len(ids) > max_sequences:
            ids = np.sort(np.random.default_rng(seed).choice(ids, max_sequences, replace=False))
        rows = {int(s): np.flatnonzero(seq == s) for s in ids}
        wanted = np.sort(np.concatenate(list(rows.values())))
        pts = dict(zip(wanted.tolist(), points_ds[wanted].astype(float), strict=True))
    if params is None and source == "msm" and file_params is not None:
        try:
            params = MSMParams(**json.loads(attr_text(file_params)))
        except (TypeError, ValueError) as e:
            raise BadInput(path, f"unreadable msm_params attribute ({e})") from None
    params = params or MSMParams()
    model = MSM(params)
    frame = None
    sequences = []
    for s, r in rows.items():
        r = r[np.argsort(step[r], kind="stable")]
        if step[r[0]] != 0:
            raise BadInput(path, f"sequence {s} has no rest state (step 0)")
        if len(r) < 2:
            continue
        rest = pts[int(r[0])]
        loads = fvec[r[1:]] if fvec is not None else None
        if source == "msm" and rest.shape[0] == model.N:
            if np.abs(rest - model.rest).max() > 1e-6:
                raise BadInput(path, f"sequence {s}: rest points are not the MSM grid")
            here = (np.eye(3), np.zeros(3))
        else:
            frame = frame or _grid_frame(path, model, rest, tip[r[0]], loads)
            here = frame
        rest_g = _to_grid(rest, here)
        loads_g = (loads @ here[0].T if loads is not None and np.isfinite(loads).all()
                   else force[r[1:], None] * np.array([0.0, 0.0, -1.0]))
        sequences.append(MeasuredSequence(
            node=int(_nearest_masses(model, _to_grid(tip[r[0]][None], here))[0]),
            masses=_nearest_masses(model, rest_g), rest=rest_g, forces=loads_g,
            points=np.stack([_to_grid(pts[int(i)], here) for i in r[1:]])))
    if not sequences:
        raise BadInput(path, "no sequence with a rest state and a loaded state to fit")
    return sequences, params


def mean_distance(params: MSMParams, sequences: list[MeasuredSequence],
                  tol: float = FIT_TOL, max_iter: int = FIT_MAX_ITER) -> float:
    """Mean distance (m) over the loaded states' points between measurement and MSM.

    Raises :class:`MSMError` where a solve does not settle within ``max_iter`` iterations.
    """
    model = MSM(params)
    solver = StaticSolver(model, tol, max_iter)
    total, count = 0.0, 0
    with blas_threads(1):
        for seq in sequences:
            solver.reset()
            x = prev = model.rest
            for load, measured in zip(seq.forces, seq.points, strict=True):
                guess = x if x is prev else 2 * x - prev
                prev, x = x, solver.solve(guess, model.load(seq.node, load))
                dist = np.linalg.norm(seq.rest + (x - model.rest)[seq.masses] - measured, axis=1)
                dist = dist[np.isfinite(dist)]          # a marker missing at rest or here
                total += float(dist.sum())
                count += len(dist)
    if count == 0:
        raise BadInput(None, "no finite measured point to compare with the MSM")
    return total / count


def fit_msm(sequences: list[MeasuredSequence], params: MSMParams,
            start: tuple[float, float] = (100.0, 21.0), rel_tol: float = 1e-3) -> FitResult:
    """Spring constants (k_between, k_fixed) minimising :func:`mean_distance`.

    The start is evaluated first: where the MSM cannot settle there, or the distance is not
    finite, :class:`BadInput` says so at once (a search from there would only meet failing
    trials). A result that is not finite is refused the same way.
    """
    if min(start) <= 0 or not all(map(math.isfinite, start)):
        raise BadInput("--start", f"constants must be finite and positive, got {start}")

    def distance(log_k: np.ndarray) -> float:
        kb, kf = np.exp(log_k)
        return mean_distance(replace(params, k_between=float(kb), k_fixed=float(kf)),
                             sequences)

    x0 = np.log(np.asarray(start, dtype=float))
    at_start = f"at --start {start[0]:g} {start[1]:g} N/m"
    try:
        f0 = distance(x0)
    except MSMError as e:
        raise BadInput("--start", f"the MSM cannot settle {at_start} ({e.what}); start from "
                                  "constants nearer the expected ones") from None
    if not math.isfinite(f0):
        raise BadInput("--start", f"the mean distance {at_start} is not finite ({f0})")
    known = {x0.tobytes(): f0}

    def objective(log_k: np.ndarray) -> float:
        key = np.asarray(log_k, dtype=float).tobytes()
        if key not in known:
            try:
                known[key] = distance(log_k)
            except MSMError:
                known[key] = math.inf        # a trial the solver cannot settle is no optimum
        return known[key]

    simplex = np.array([x0, x0 + [0.2, 0.0], x0 + [0.0, 0.2]])
    res = minimize(objective, x0, method="Nelder-Mead",
                   options={"initial_simplex": simplex, "xatol": rel_tol, "fatol": 1e-10,
                            "maxfev": 300})
    if not math.isfinite(res.fun):
        raise BadInput("--start", f"the fit found no constants where the MSM settles "
                                  f"(best mean distance {res.fun}) starting {at_start}")
    kb, kf = np.exp(res.x)
    return FitResult(
        k_between=float(kb), k_fixed=float(kf), mean_distance_m=float(res.fun),
        start_distance_m=f0, evaluations=len(known),
        sequences=len(sequences), states=sum(len(s.forces) for s in sequences))


def _grid_frame(path: Path, model: MSM, rest: np.ndarray, tip: np.ndarray,
                loads: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Rotation and shift taking lab coordinates to the grid frame (see module doc)."""
    finite = np.isfinite(rest).all(axis=1)
    surface = rest[finite & (np.linalg.norm(rest - tip, axis=1) > TIP_RADIUS)]
    if len(surface) < 3:
        raise BadInput(path, "fewer than 3 finite rest points: cannot place the MSM grid")
    centre = surface.mean(axis=0)
    normal = np.linalg.svd(surface - centre)[2][2]
    if loads is not None and np.isfinite(loads).all():
        push = float((loads @ normal).sum())
    else:
        push = float(normal[2])          # no force vectors: the lab's z is up
    if push > 0:
        normal = -normal                 # the force pushes into the surface, against +z
    axis = np.eye(3)[0] if abs(normal[0]) < 0.9 else np.eye(3)[1]
    ex = axis - (axis @ normal) * normal
    ex /= np.linalg.norm(ex)
    ey = np.cross(normal, ex)
    yaw = _layout_yaw((surface - centre) @ np.stack([ex, ey]).T)
    ex, ey = math.cos(yaw) * ex + math.sin(yaw) * ey, -math.sin(yaw) * ex + math.cos(yaw) * ey
    rot = np.stack([ex, ey, normal])
    grid_centre = np.array([model.params.size / 2, model.params.size / 2, 0.0])
    return rot, grid_centre - rot @ centre


def _layout_yaw(xy: np.ndarray) -> float:
    """In-plane angle (rad, within +-45 degrees) of the rows of a grid-like point layout.

    Each point's direction to its nearest neighbour lies along a row or a column; folded
    modulo 90 degrees (angles times 4) they agree, and their mean gives the rows' angle.
    0 when they do not agree (no grid-like layout).
    """
    if len(xy) < 2:
        return 0.0
    gap = np.linalg.norm(xy[:, None] - xy[None], axis=2)
    np.fill_diagonal(gap, np.inf)
    step = xy[gap.argmin(axis=1)] - xy
    folded = np.exp(4j * np.arctan2(step[:, 1], step[:, 0])).mean()
    return float(np.angle(folded) / 4) if abs(folded) >= GRID_AGREEMENT else 0.0


def _to_grid(points: np.ndarray, frame: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    rot, shift = frame
    return points @ rot.T + shift


def _nearest_masses(model: MSM, points: np.ndarray) -> np.ndarray:
    """Index of the grid mass nearest each point's (x, y)."""
    h, n = model.params.spacing, model.n
    ij = np.clip(np.rint(points[:, [1, 0]] / h), 0, n - 1).astype(int)
    return ij[:, 0] * n + ij[:, 1]


"""The model at the extremes: where its answers degrade, and whether it says so.

Through :class:`train.Predictor` (what a VR scene calls) on a run's single-step test examples
whose points are all tracked at both ends, each extreme swept on its own:

- frame offset: points and C shifted in the plane (x) and along the normal (z); errors
  against the shifted truth, and how many calls were flagged (``extrapolating``) or refused;
- press size: the press vector (tip end - tip start) scaled from 0 to 4 times its measured
  length; the predicted change of force and largest displacement (0 must give exactly 0);
- depth: the tip driven straight down from its start, 1 to 45 mm (the phantom is 32 mm thick);
- ordering: the points (and a 32 x 32 grid over their footprint, where neighbour distances
  tie) given in 5 random orders; the largest change of any point and of the
  force after putting them back in order (0 for a permutation-equivariant model).

A row counts a call as flagged when the predictor set ``extrapolating`` (it also warns).
``python benchmarks/extremes.py --run RUN [--msm-run RUN]`` prints the tables; the
speed-accuracy report includes them (``extreme_rows``).
"""

from __future__ import annotations

import argparse
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
from speed_accuracy_report import extremes_text

from train.data import SETS
from train.evaluation.run_errors import load_run
from train.inference.predictor import Predictor

Example = tuple[np.ndarray, np.ndarray, np.ndarray, float]   # points, target, C, dF
SHIFTS_MM = (0.0, 1.0, 10.0, 50.0, 200.0, 1000.0)
PRESS_FACTORS = (0.0, 1e-3, 0.1, 0.5, 1.0, 2.0, 4.0)
DEPTHS_MM = (1.0, 5.0, 10.0, 20.0, 32.0, 45.0)
ORDERINGS = 5


def test_examples(run_dir: Path, limit: int = 64) -> list[Example]:
    """Up to ``limit`` single-step test examples of the run's fold with every point valid."""
    run = load_run(run_dir)
    s = run.states
    pairs = s.pairs[SETS[0]][np.asarray(run.test[SETS[0]], dtype=np.int64)].numpy()
    out = []
    for a, b in pairs:
        if bool(s.valid[a].all() and s.valid[b].all()):
            c = np.concatenate([s.tip[a].numpy(), s.tip[b].numpy()]).astype(np.float32)
            out.append((s.points[a].numpy(), s.points[b].numpy(), c,
                        float(s.force[b] - s.force[a])))
        if len(out) == limit:
            break
    return out


def call(pred: Predictor, points: np.ndarray, c: np.ndarray
         ) -> tuple[np.ndarray, float, bool] | None:
    """One prediction, with whether it was flagged; None when the predictor refused it."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            deformed, df = pred.predict(points, c)
        except ValueError:
            return None
    return deformed, df, bool(pred.extrapolating)


Move = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def sweep(pred: Predictor, examples: list[Example], move: Move, truth: bool) -> dict:
    """Mean response over ``examples`` moved by ``move`` (points, C) -> (points, C): the
    errors against the moved truth when ``truth``, else the size of the answer."""
    ld, fe, df_abs, disp, flagged, refused = [], [], [], [], 0, 0
    for points, target, c, df in examples:
        p, cm = move(points, c)
        r = call(pred, p, cm)
        if r is None:
            refused += 1
            continue
        deformed, dfp, flag = r
        flagged += flag
        df_abs.append(abs(dfp))
        disp.append(float(np.linalg.norm(deformed - p, axis=1).max()) * 1e3)
        if truth:
            shift = p - points
            ld.append(float(np.linalg.norm(deformed - (target + shift), axis=1).mean()) * 1e3)
            fe.append(abs(dfp - df))
    row = {"flagged": flagged / len(examples), "refused": refused / len(examples)}
    if df_abs:
        row.update(dforce_n=float(np.mean(df_abs)), disp_mm=float(np.mean(disp)))
    if ld:
        row.update(ld_mm=float(np.mean(ld)), force_n=float(np.mean(fe)))
    return row


def shifted(axis: int, metres: float) -> Move:
    """Points and C moved by ``metres`` along ``axis``."""
    d = np.zeros(3, np.float32)
    d[axis] = metres
    return lambda p, c: (p + d, c + np.tile(d, 2))


def pressed(factor: float) -> Move:
    """The press vector scaled by ``factor`` about the tip's start."""
    return lambda p, c: (p, np.concatenate([c[:3], c[:3] + factor * (c[3:] - c[:3])]))


def driven(depth_m: float) -> Move:
    """The tip driven ``depth_m`` straight down (-z) from its start."""
    return lambda p, c: (p, np.concatenate([c[:3], c[:3] - np.array([0, 0, depth_m],
                                                                      np.float32)]))


def ordering_row(pred: Predictor, examples: list[Example], seed: int) -> dict:
    """The largest change of any point (mm) and of the force (N) when the points come in
    another order, over ``ORDERINGS`` random orders of each example."""
    rng = np.random.default_rng(seed)
    dp = dfo = 0.0
    for points, _, c, _ in examples:
        base = call(pred, points, c)
        for _ in range(ORDERINGS):
            perm = rng.permutation(len(points))
            r = call(pred, points[perm], c)
            if base is None or r is None:
                continue
            back = np.empty_like(r[0])
            back[perm] = r[0]
            dp = max(dp, float(np.abs(back - base[0]).max()) * 1e3)
            dfo = max(dfo, abs(r[1] - base[1]))
    return {"points": len(examples[0][0]), "max_point_mm": dp, "max_force_n": dfo}


def grid_examples(examples: list[Example], n: int = 32) -> list[Example]:
    """The examples' presses on an ``n`` x ``n`` grid spanning their points' footprint at
    z = 0: a regular grid, where neighbour distances tie (as on the MSM's surface)."""
    lo, hi = examples[0][0][:, :2].min(0), examples[0][0][:, :2].max(0)
    u, v = np.meshgrid(np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n))
    grid = np.stack([u.ravel(), v.ravel(), np.zeros(n * n)], 1).astype(np.float32)
    return [(grid, grid, c, df) for _, _, c, df in examples]


def extreme_rows(run_dir: Path, msm_run_dir: Path | None = None, seed: int = 0,
                 limit: int = 64) -> dict:
    """Every sweep on ``run_dir``'s test examples; the ordering also on ``msm_run_dir``'s."""
    pred = Predictor.load(run_dir)
    ex = test_examples(run_dir, limit)
    res = {
        "offset": [{"test": f"{'xz'[a // 2]} {mm:g} mm",
                    **sweep(pred, ex, shifted(a, mm * 1e-3), truth=True)}
                   for a in (0, 2) for mm in SHIFTS_MM],
        "press": [{"factor": f, **sweep(pred, ex, pressed(f), truth=f == 1.0)}
                  for f in PRESS_FACTORS],
        "depth": [{"depth_mm": d, **sweep(pred, ex, driven(d * 1e-3), truth=False)}
                  for d in DEPTHS_MM],
        "ordering": [{"model": "twin", **ordering_row(pred, ex[:8], seed)},
                     {"model": "twin, 32 x 32 grid",
                      **ordering_row(pred, grid_examples(ex[:2]), seed)}],
    }
    if msm_run_dir is not None:
        res["ordering"].append({"model": "MSM",
                                **ordering_row(Predictor.load(msm_run_dir),
                                               test_examples(msm_run_dir, 4), seed)})
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--run", type=Path, required=True, help="a run folder (lab data)")
    ap.add_argument("--msm-run", type=Path, default=None, help="a run on MSM data")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    print(extremes_text(extreme_rows(a.run, a.msm_run, a.seed)))


if __name__ == "__main__":
    main()

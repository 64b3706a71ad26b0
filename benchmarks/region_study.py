"""Region of interest: what running the cGNN near the press only buys in time and costs in error.

An MSM model is trained on the 32 x 32 grid (1024 points), with the recipe of docs/model.md's
"Training that learns" (``ours``, :mod:`train.training.recipes`: head offsets, balanced loss,
rotation, lr 2e-3; without its average of the weights, as measured), or taken from ``--run``
(a run trained elsewhere, e.g. on a GPU). Presses it never saw are simulated on the same surface
and sampled at its 1024 masses and at a 64 x 64 lattice (4096 points, the same physics seen
denser; the model never trained at that density, so its error there is the whole model's too).
For each radius R, through :class:`train.Predictor` on the same presses: mean L_d and force
error against the MSM's truth and against the whole model, and the median latency of
``predict`` (a mesh pressed again: the scene is reused). The default radius is the smallest
whose mean L_d against truth is within 5 % of the whole model's at both sizes; it proves
something only where the whole model beats "nothing moves" (the report says when it does not).

A model that learns displacement at 1024 points needs more than a CPU's few minutes (~12 s an
epoch on 2 cores): 15 epochs on 16 presses learn none, 60 epochs on 64 locations x 4
directions do (a few minutes on a GPU)::

    python benchmarks/region_study.py --out out/region [--epochs 15]            (~8 min, 2 cores)
    python benchmarks/region_study.py --out out/region64 --device cuda --epochs 60 \
        --locations 64 --directions 4
    python benchmarks/region_study.py --out out/region --run out/region64/msm32_run   (time it here)
"""

from __future__ import annotations

import argparse
import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch
from bench_cgnn import median_ms
from speed_accuracy_report import NOTHING, region_text

from sim.msm.msm import MSMParams
from sim.msm.msm_protocol import Protocol, draw_plan
from sim.msm.msm_simulate import simulate_plan
from sim.msm.simulate_stage import generate
from split.split_stage import build_manifest, default_plan, write_manifest
from train.inference.predictor import Predictor
from train.training.recipes import OURS
from train.training.train_params import TrainInputs, TrainParams
from train.training.train_stage import run_train

RADII_MM = (5, 10, 15, 20, 30, 45)
TOLERANCE = 0.05          # the default radius changes mean L_d by less than this
TRAIN = Protocol(locations=16, directions=2, steps=6, max_angle_deg=30.0)
UNSEEN = Protocol(locations=4, directions=2, steps=8, max_angle_deg=30.0, seed=1)


def model(out: Path, epochs: int, lr: float, device: str, seed: int,
          protocol: Protocol = TRAIN) -> Path:
    """The 1024-point MSM run (trained here once, resumed or reused after): its folder."""
    data, splits, run = out / "msm32.h5", out / "msm32_splits.json", out / "msm32_run"
    if not splits.is_file():
        out.mkdir(parents=True, exist_ok=True)
        generate(data, protocol, MSMParams(n=32), workers=min(2, os.cpu_count() or 1))
        write_manifest(splits, build_manifest(data, default_plan(data, None, None, 1, seed)))
    opts, config = OURS.settings(epochs=epochs, lr=lr, seed=seed, ema=None)
    run_train(TrainInputs(data, splits), run, TrainParams(opts, config, device))
    return run


def presses(side: int) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, float]]:
    """Unseen presses at a side x side lattice of the 32 x 32 MSM: (rest (N, 3), deformed,
    C (6,), change of force) from rest to each load step."""
    params = MSMParams(n=32)
    plan = draw_plan(UNSEEN, params.n * params.n)
    layout = None
    if side != params.n:
        x = np.linspace(0.0, params.size, side)
        xx, yy = np.meshgrid(x, x)
        layout = np.stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)], 1)
    sim = simulate_plan(plan, params, layout=layout)
    pts = sim.points if layout is None else sim.points[:, :-1]          # the tip is not a point
    per = UNSEEN.steps + 1
    out = []
    for first in range(0, len(pts), per):
        for t in range(1, per):
            cond = np.r_[sim.tips[first], sim.tips[first + t]].astype(np.float32)
            out.append((pts[first], pts[first + t], cond, UNSEEN.fmax * t / UNSEEN.steps))
    return out


def scores(pred: Predictor, cases: list, radius: float | None, whole: list | None,
           repeats: int) -> tuple[dict, list]:
    """Errors against truth (and against ``whole``'s answers) and the median latency."""
    answers = [pred.predict(p, c, region=radius) for p, _, c, _ in cases]
    pairs = list(zip(answers, cases, strict=True))
    ld = [np.linalg.norm(a[0] - y, axis=1).mean() for a, (_, y, _, _) in pairs]
    fe = [abs(a[1] - f) for a, (_, _, _, f) in pairs]
    row = {"setting": "whole model" if radius is None else f"R = {radius * 1e3:g} mm",
           "radius_mm": None if radius is None else radius * 1e3, "points": len(cases[0][0]),
           "ld_mm": 1e3 * float(np.mean(ld)), "force_n": float(np.mean(fe))}
    if whole is not None:
        same = list(zip(answers, whole, strict=True))
        row["ld_vs_whole_mm"] = 1e3 * float(np.mean([np.linalg.norm(a[0] - w[0], axis=1).mean()
                                                     for a, w in same]))
        row["force_vs_whole_n"] = float(np.mean([abs(a[1] - w[1]) for a, w in same]))
    p, _, c, _ = cases[len(cases) // 2]
    row["ms"] = median_ms(lambda: pred.predict(p, c, region=radius), repeats, lambda: None)
    return row, answers


def nothing_moves(cases: list) -> dict:
    """The reference that learns nothing: every point stays at rest, the force is zero."""
    return {"setting": NOTHING, "points": len(cases[0][0]),
            "ld_mm": 1e3 * float(np.mean([np.linalg.norm(y - p, axis=1).mean()
                                          for p, y, _, _ in cases])),
            "force_n": float(np.mean([f for _, _, _, f in cases]))}


def region_rows(out: Path, epochs: int = 15, lr: float = OURS.options["lr"], device: str = "cpu",
                seed: int = 0, repeats: int = 30, run: Path | None = None,
                protocol: Protocol = TRAIN) -> dict:
    """Every row (1024 and 4096 points, each radius and the whole model), and the default.
    ``run``: time and score that trained run instead of training one."""
    run = run or model(out, epochs, lr, device, seed, protocol)
    pred = Predictor.load(run, device)
    rows = []
    for side in (32, 64):
        cases = presses(side)
        first, whole = scores(pred, cases, None, None, repeats)
        rows += [nothing_moves(cases), first]
        rows += [scores(pred, cases, r / 1e3, whole, repeats)[0] for r in RADII_MM]
    return {"rows": rows, "default_mm": pick_default(rows), "tolerance": TOLERANCE}


def pick_default(rows: list[dict]) -> float | None:
    """The smallest radius within ``TOLERANCE`` of the whole model's mean L_d at every size."""
    whole = {r["points"]: r["ld_mm"] for r in rows if r.get("setting") == "whole model"}
    for radius in RADII_MM:
        mine = [r for r in rows if r.get("radius_mm") == radius]
        if all(abs(r["ld_mm"] / whole[r["points"]] - 1) < TOLERANCE for r in mine):
            return float(radius)
    return None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/region"))
    ap.add_argument("--epochs", type=int, default=15)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--device", choices=["cpu", "cuda"], default="cpu")
    ap.add_argument("--locations", type=int, default=TRAIN.locations,
                    help="MSM training locations (a new --out for another protocol)")
    ap.add_argument("--directions", type=int, default=TRAIN.directions)
    ap.add_argument("--run", type=Path, help="a trained run to time and score (no training)")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    protocol = replace(TRAIN, locations=a.locations, directions=a.directions)
    result = region_rows(a.out, a.epochs, device=a.device, run=a.run, protocol=protocol)
    print(f"model: {a.run or a.out / 'msm32_run'}")
    print(region_text(result))


if __name__ == "__main__":
    main()

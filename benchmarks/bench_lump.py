"""Learning a lab with a lump: the force over the lump against away from it, per way of training.

    python benchmarks/bench_lump.py [--seed 42] [--lump 32,17] [--out /tmp/bench_lump] \
        [--ways rotate rotate-force solid] [--jobs 2]

Issue 58's lab: a twin session ``synth --locations 4x4 --repeats 2 --inclusion X,Y,10,12,3``
(the lump 3 x stiffer, 12 mm in radius, its centre 10 mm deep) taken through ingest, sync,
extract and split (5 folds), into ``OUT/seed<S>`` (reused when there). Each way fine-tunes
every fold from the shipped generic model, 100 epochs at the recipe's 2e-3 (``--recipe
ours``), and is scored by ``eval --truth`` over the lump and away from it:

- ``rotate``: the recipe as it is (every example turned about the normal);
- ``rotate-force``: ``--no-rotate-force``, the force learnt from unturned presses only;
- ``no-rotate``: no rotation at all;
- ``solid``: per fold ``fit-solid`` (the session's interior, its ratio given),
  ``simulate --solid`` (32 places x 3 directions), the shipped model pre-trained 40 epochs on
  it, then fine-tuned; both trainings ``--no-rotate-force``.

Printed per way: L_d and the force's error over the lump and away, their ratio (issue 58's
target: the force over the lump <= 1.3 x away), the force's 90 % interval's coverage over and
away (85-95 %), and each fold's gain over the best reference there (>= 30 %), beside the
references. Each command runs single-threaded, ``--jobs`` at a time.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from data_schema.metrics_doc import LumpPart, Scores, validate_metrics  # noqa: E402
from pipeline.demo_plan import QUICK, Lab, session_steps, solid_steps  # noqa: E402
from train.generic_model import SHIPPED  # noqa: E402

FOLDS = QUICK.folds
STATES = "session_states.h5"      # session_steps' states file, in the lab's folder
RECIPE = ("--recipe", "ours", "--lr", "0.002", "--batch", "32", "--seed", "0", "--no-rrd")
FINE_TUNE = ("--epochs", str(QUICK.finetune_epochs), *RECIPE)
WAYS = {"rotate": (), "rotate-force": ("--no-rotate-force",), "no-rotate": ("--no-rotate",),
        "solid": ("--no-rotate-force",)}


def pipeline(*args: str) -> None:
    """One ``pipeline`` command, single-threaded, its output kept quiet."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    subprocess.run([sys.executable, "-m", "pipeline", "-q", *args], check=True, env=env,
                   stdout=subprocess.DEVNULL)


def session(folder: Path, seed: int, lump: str) -> None:
    """The lab's session, states and manifest, as the demo makes them (unless already there)."""
    if (folder / "splits.json").is_file():
        return
    lab = Lab(inclusions=(f"{lump},10,12,3",))
    for step in session_steps(folder, "session", seed, "4x4", 2, lab):
        pipeline(*step.args, "--no-rrd")
    pipeline("split", str(folder / STATES), "--out", str(folder / "splits.json"), "--no-rrd")


def fold_run(folder: Path, way: str, fold: int) -> None:
    """One fold of one way: for ``solid`` the demo's steps (the fold's solid fitted, pressed
    and pre-trained on: ``pipeline demo --pretraining solid``'s), then its fine-tuning."""
    run = folder / "runs" / f"{way}_{fold}"
    if (run / "best.pt").is_file():
        return
    init = "generic"
    if way == "solid":
        states, splits = folder / STATES, folder / "splits.json"
        steps = solid_steps(folder, QUICK, states, splits, (*RECIPE, *WAYS[way]), SHIPPED)
        mine = steps[4 * fold:4 * fold + 4]         # fit-solid, simulate, split, pre-training
        for step in mine:
            if not all(Path(o).exists() for o in step.outputs):
                pipeline(*step.args)
        init = str(mine[-1].outputs[0])
    pipeline("train", "--data", str(folder / STATES), "--splits",
             str(folder / "splits.json"), "--fold", str(fold), "--out", str(run), "--init",
             init, *FINE_TUNE, *WAYS[way])


def scored(folder: Path, way: str) -> Scores:
    """``eval --truth`` of the way's five runs."""
    out = folder / f"metrics_{way}.json"
    if not out.is_file():
        pipeline("eval", *(str(folder / "runs" / f"{way}_{k}") for k in range(FOLDS)),
                 "--truth", str(folder / "session" / "truth.h5"), "--out", str(out), "--no-rrd")
    return Scores.from_json(validate_metrics(out))


def force_cover(part: LumpPart) -> float:
    """The share of the part's changes of force inside their 90 % interval (NaN: none)."""
    level = part.intervals.at(0.9) if part.intervals else None
    return float("nan") if level is None or level.force_coverage is None \
        else level.force_coverage


def weighted(parts: list[LumpPart], value: Callable[[LumpPart], float | None]) -> float:
    """``value`` over the parts' examples (each part weighted by its count)."""
    return sum((value(p) or 0.0) * p.metrics.n for p in parts) / sum(p.metrics.n for p in parts)


def cells(parts: list[LumpPart]) -> dict[str, float | str]:
    """One part of the lump (over or away), pooled over the folds."""
    gains = [p.gain.ld_gain or 0.0 for p in parts]
    return {"ld": weighted(parts, lambda p: p.metrics.ld_mean_mm),
            "force": weighted(parts, lambda p: p.metrics.force_abs_n),
            "cover": weighted(parts, force_cover), "gains": f"{min(gains):.0%}-{max(gains):.0%}",
            "ref_ld": weighted(parts, lambda p: p.gain.ld_reference_mm),
            "ref_force": weighted(parts, lambda p: p.gain.force_reference_n),
            "n": sum(p.metrics.n for p in parts)}


def table(scores: Scores) -> tuple[dict, dict]:
    """Over the lump and away from it: :func:`cells` of every fold's part."""
    over, away = ([p for r in scores.runs if r.lump and (p := r.lump.parts()[name])]
                  for name in ("over", "away"))
    return cells(over), cells(away)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=42)
    ap.add_argument("--lump", default="32,17", help="X,Y mm: the lump's centre on the footprint")
    ap.add_argument("--out", type=Path, default=Path("/tmp/bench_lump"))
    ap.add_argument("--ways", nargs="+", choices=list(WAYS), default=["rotate", "rotate-force",
                                                                      "solid"])
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args()
    folder = a.out / f"seed{a.seed}"
    session(folder, a.seed, a.lump)
    with ThreadPoolExecutor(a.jobs) as pool:
        list(pool.map(lambda job: fold_run(folder, *job),
                      [(way, k) for way in a.ways for k in range(FOLDS)]))
    print(f"seed {a.seed}, lump ({a.lump}) mm; over the lump / away: mean L_d (mm), force "
          "error (N), their ratio, the force's 90 % interval's coverage, each fold's gain "
          "over the best reference")
    print("| way | over: L_d, force | away: L_d, force | force over / away | force in 90 %, "
          "over / away | folds' gain, over / away |\n|---|---|---|---|---|---|")
    for way in a.ways:
        o, w = table(scored(folder, way))
        print(f"| {way} | {o['ld']:.3f} mm, {o['force']:.3f} N | {w['ld']:.3f} mm, "
              f"{w['force']:.3f} N | {o['force'] / w['force']:.2f} x | {o['cover']:.1%} / "
              f"{w['cover']:.1%} | {o['gains']} / {w['gains']} |")
    print(f"| best reference | {o['ref_ld']:.3f} mm, {o['ref_force']:.3f} N | {w['ref_ld']:.3f} "
          f"mm, {w['ref_force']:.3f} N | | | |  ({o['n']} / {w['n']} test examples)")


if __name__ == "__main__":
    main()

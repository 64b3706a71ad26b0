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
import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

FOLDS = 5
TRAIN = ("--recipe", "ours", "--epochs", "100", "--lr", "0.002", "--batch", "32", "--seed",
         "0", "--no-rrd")
WAYS = {"rotate": (), "rotate-force": ("--no-rotate-force",), "no-rotate": ("--no-rotate",),
        "solid": ("--no-rotate-force",)}


def pipeline(*args: str) -> None:
    """One ``pipeline`` command, single-threaded, its output kept quiet."""
    env = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    subprocess.run([sys.executable, "-m", "pipeline", "-q", *args], check=True,
                   env={**os.environ, **env}, stdout=subprocess.DEVNULL)


def session(folder: Path, seed: int, lump: str) -> None:
    """The lab's session, states and manifest (made unless already there)."""
    if (folder / "splits.json").is_file():
        return
    pipeline("synth", str(folder / "session"), "--seed", str(seed), "--locations", "4x4",
             "--repeats", "2", "--inclusion", f"{lump},10,12,3", "--no-rrd")
    pipeline("ingest", str(folder / "session"), "--out", str(folder / "session.mcap"),
             "--no-rrd")
    pipeline("sync", str(folder / "session.mcap"), "--out", str(folder / "synced.h5"),
             "--no-rrd")
    pipeline("extract", str(folder / "synced.h5"), "--out", str(folder / "states.h5"),
             "--no-rrd")
    pipeline("split", str(folder / "states.h5"), "--out", str(folder / "splits.json"),
             "--no-rrd")


def fold_run(folder: Path, way: str, fold: int) -> None:
    """One fold of one way: its pre-training on the solid (``solid``), then its fine-tuning."""
    run = folder / "runs" / f"{way}_{fold}"
    if (run / "best.pt").is_file():
        return
    init = "generic"
    if way == "solid":
        d = folder / "solid" / f"fold{fold}"
        pipeline("fit-solid", str(folder / "states.h5"), "--splits", str(folder / "splits.json"),
                 "--fold", str(fold), "--session", str(folder / "session"), "--out",
                 str(d / "solid.json"), "--no-rrd")
        pipeline("simulate", "--solid", str(d / "solid.json"), "--layout",
                 str(folder / "states.h5"), "--locations", "32", "--directions", "3",
                 "--max-angle", "20", "--out", str(d / "states.h5"), "--no-rrd")
        pipeline("split", str(d / "states.h5"), "--out", str(d / "splits.json"), "--folds", "1",
                 "--no-rrd")
        pipeline("train", "--data", str(d / "states.h5"), "--splits", str(d / "splits.json"),
                 "--out", str(d / "pre"), "--init", "generic", *TRAIN[:2], "--epochs", "40",
                 *TRAIN[4:], *WAYS[way])
        init = str(d / "pre" / "best.pt")
    pipeline("train", "--data", str(folder / "states.h5"), "--splits",
             str(folder / "splits.json"), "--fold", str(fold), "--out", str(run), "--init",
             init, *TRAIN, *WAYS[way])


def scored(folder: Path, way: str) -> dict:
    """``eval --truth`` of the way's five runs: the metrics document."""
    out = folder / f"metrics_{way}.json"
    if not out.is_file():
        pipeline("eval", *(str(folder / "runs" / f"{way}_{k}") for k in range(FOLDS)),
                 "--truth", str(folder / "session" / "truth.h5"), "--out", str(out), "--no-rrd")
    return json.loads(out.read_text())


def pooled(rows: list[dict], value) -> float:  # noqa: ANN001 (a row's number)
    """``value`` over the examples of every part's row (each weighted by its count)."""
    return sum(value(p) * p["metrics"]["n"] for p in rows) / sum(p["metrics"]["n"]
                                                                 for p in rows)


def force_cover(part: dict) -> float:
    """The share of the part's changes of force inside their 90 % interval."""
    return next(v["force_coverage"] for v in part["intervals"]["levels"]
                if abs(v["level"] - 0.9) < 1e-9)


def parts(doc: dict) -> dict[str, dict]:
    """Per part of the lump (over, away), pooled over the folds: L_d, force, the force's
    90 % coverage, the best references, and the folds' gains."""
    found = {}
    for part in ("over", "away"):
        rows = [r["lump"][part] for r in doc["runs"] if r["lump"][part]]
        found[part] = {
            "n": sum(p["metrics"]["n"] for p in rows),
            "ld": pooled(rows, lambda p: p["metrics"]["ld_mean_mm"]),
            "force": pooled(rows, lambda p: p["metrics"]["force_abs_n"]),
            "cover": pooled(rows, force_cover),
            "ref_ld": pooled(rows, lambda p: p["gain"]["ld_reference_mm"]),
            "ref_force": pooled(rows, lambda p: p["gain"]["force_reference_n"]),
            "gains": [p["gain"]["ld_gain"] for p in rows]}
    return found


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
        p = parts(scored(folder, way))
        o, w = p["over"], p["away"]
        gains = " / ".join(f"{min(x['gains']):.0%}-{max(x['gains']):.0%}" for x in (o, w))
        print(f"| {way} | {o['ld']:.3f} mm, {o['force']:.3f} N | {w['ld']:.3f} mm, "
              f"{w['force']:.3f} N | {o['force'] / w['force']:.2f} x | {o['cover']:.1%} / "
              f"{w['cover']:.1%} | {gains} |")
    print(f"| best reference | {o['ref_ld']:.3f} mm, {o['ref_force']:.3f} N | {w['ref_ld']:.3f} "
          f"mm, {w['ref_force']:.3f} N | | | |  ({o['n']} / {w['n']} test examples)")


if __name__ == "__main__":
    main()

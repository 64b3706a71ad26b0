"""Does the model learn? The quick demo's protocol on several twin seeds, scored beside the
predictors that learn nothing (docs/results.md, Learning), so anyone can re-measure it.

    python benchmarks/bench_learning.py --seeds 0 1 2 [--out /tmp/bench_learning] [--jobs 2]
    python benchmarks/bench_learning.py --network paper --out /tmp/bench_paper_network
    python benchmarks/bench_learning.py --networks head-offsets tip-offsets paper --seeds 0 1 2

The demo trains with the recipe ``ours`` (:mod:`train.training.recipes`, ``pipeline train --recipe
ours``). ``--network`` runs another network with the rest of the recipe (``pipeline demo
--network``: the tip's offsets in the heads or in the first layer, or the paper's network):
what each costs in accuracy beside what it costs in time (docs/results.md).

Per seed it runs ``pipeline demo --quick --seed S`` (each seed its own phantom session and
calibration presses; unchanged steps are skipped on a second run) and prints, from its
metrics.json and scarcity study:

- per variant (the references, scratch "cGNN/Exp", transfer learning "TL", the MSM model on
  its own test set): mean L_d as the mean of the folds' means, the folds worse than "nothing
  moves" and than "nearest press", the force absolute error;
- TL against scratch (pooled mean L_d, folds better) and the scarcity curve;
- the demo's wall time.

``--networks`` runs the demo for each network into ``OUT/<network>/seed<S>`` and ends with the
networks side by side, like for like: per seed, scratch and TL mean L_d, each fold's worst gain
over the best reference, TL's force error, and each network's L_d against the first one named
(``--table-only``: that table from the folders a former run left).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from data_schema.metrics_doc import (  # noqa: E402
    FORCE_LINEAR,
    NEAREST_PRESS,
    NOTHING_MOVES,
    REFERENCES,
    RunRow,
    Scores,
)
from pipeline.demo_plan import NETWORKS  # noqa: E402
from pipeline.demo_targets import scarcity_rows, variant_of  # noqa: E402
from train.evaluation.scarcity import curve  # noqa: E402


def run_demo(out: Path, seed: int, jobs: int | None, extra: tuple[str, ...] = ()) -> float:
    """``pipeline demo --quick`` for one seed (``extra``: more demo options); its wall time
    (s)."""
    cmd = [sys.executable, "-m", "pipeline", "-q", "demo", "--quick", "--out", str(out),
           "--seed", str(seed), *extra] + (["--jobs", str(jobs)] if jobs else [])
    tic = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - tic


def variant_row(runs: list[RunRow], name: str) -> str:
    """One table row: fold-mean L_d, folds worse than each reference, force error."""
    ld = [r.metrics.all.ld_mean_mm for r in runs]
    worse = [sum(r.metrics.all.ld_mean_mm > r.references[ref].ld_mean_mm for r in runs)
             for ref in (NOTHING_MOVES, NEAREST_PRESS)]
    force = np.mean([r.metrics.all.force_abs_n for r in runs])
    return (f"| {name} | {np.mean(ld):.3f} | {worse[0]} of {len(runs)} | {worse[1]} of "
            f"{len(runs)} | {force:.3f} |")


def reference_row(runs: list[RunRow]) -> str:
    """The references' row on the same folds."""
    ld = [np.mean([r.references[ref].ld_mean_mm for r in runs])
          for ref in (NOTHING_MOVES, NEAREST_PRESS)]
    force = np.mean([r.references[FORCE_LINEAR].force_abs_n for r in runs])
    return (f"| {' / '.join(REFERENCES)} | {ld[0]:.3f} / {ld[1]:.3f} | – "
            f"| – | {force:.3f} (linear) |")


def report(out: Path, seed: int, seconds: float) -> None:
    """Print one seed's table from its demo folder."""
    by = runs_by_variant(out, ("notl", "tl", "msm"))
    print(f"\n## seed {seed}: quick demo {seconds / 60:.1f} min\n")
    print("| run | mean L_d [mm], mean of folds | folds worse than nothing moves | folds "
          "worse than nearest press | force abs. error [N] |")
    print("|---|---|---|---|---|")
    print(reference_row(by["notl"]))
    print(variant_row(by["notl"], "cGNN/Exp (scratch)"))
    print(variant_row(by["tl"], "cGNN/MSM (TL)"))
    msm = by["msm"][0]
    print(variant_row(by["msm"], "cGNN/MSM on the MSM test set")
          + f" ({NOTHING_MOVES} {msm.references[NOTHING_MOVES].ld_mean_mm:.3f} mm, "
          f"linear force {msm.references[FORCE_LINEAR].force_abs_n:.3f} N)")
    tl = [r.metrics.all.ld_mean_mm for r in by["tl"]]
    sc = [r.metrics.all.ld_mean_mm for r in by["notl"]]
    gains = {v: ", ".join(f"{r.gain.ld_gain:+.0%}" for r in by[v]) for v in ("tl", "notl")}
    print(f"\nTL vs scratch: fold means {1 - np.mean(tl) / np.mean(sc):.0%} lower, better in "
          f"{sum(a < b for a, b in zip(tl, sc, strict=True))} of {len(tl)} folds; gain over "
          f"the best reference per fold: TL {gains['tl']}; scratch {gains['notl']}")
    rows = scarcity_rows(out)
    for name in ("TL", "no TL", NOTHING_MOVES, NEAREST_PRESS):
        groups, ld = curve(rows, name, lambda r: r.ld_mean_mm)
        print(f"scarcity {name:13}: " + ", ".join(f"{g}: {v:.3f}" for g, v in
                                                    zip(groups, ld, strict=True)) + " mm")


def runs_by_variant(out: Path, variants: tuple[str, ...]) -> dict[str, list[RunRow]]:
    """A demo folder's runs of each of ``variants`` (:func:`variant_of`), in fold order."""
    scores = Scores.from_json(json.loads((out / "metrics.json").read_text()))
    return {v: sorted((r for r in scores.runs if variant_of(r) == v), key=lambda r: r.fold)
            for v in variants}


def compare(root: Path, networks: list[str], seeds: list[int]) -> None:
    """The networks side by side on the same seeds: L_d, worst fold's gain, TL's force."""
    print("\n## The networks, like for like (mean of the 5 folds' mean L_d; worst fold's gain "
          f"over the best reference; L_d against {networks[0]})\n")
    print("| network | seed | scratch L_d [mm] | TL L_d [mm] | worst gain, scratch / TL | "
          f"TL force error [N] | scratch / TL against {networks[0]} |")
    print("|---|---|---|---|---|---|---|")
    first: dict[int, tuple[float, float]] = {}
    for net in networks:
        for seed in seeds:
            by = runs_by_variant(root / net / f"seed{seed}", ("notl", "tl"))
            ld = {v: float(np.mean([r.metrics.all.ld_mean_mm for r in by[v]])) for v in by}
            worst = {v: min(r.gain.ld_gain for r in by[v]) for v in by}
            force = np.mean([r.metrics.all.force_abs_n for r in by["tl"]])
            base = first.setdefault(seed, (ld["notl"], ld["tl"]))
            print(f"| {net} | {seed} | {ld['notl']:.3f} | {ld['tl']:.3f} | "
                  f"{worst['notl']:+.0%} / {worst['tl']:+.0%} | {force:.3f} | "
                  f"{ld['notl'] / base[0] - 1:+.1%} / {ld['tl'] / base[1] - 1:+.1%} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--out", type=Path, default=Path("/tmp/bench_learning"))
    ap.add_argument("--jobs", type=int, default=None)
    ap.add_argument("--network", choices=NETWORKS, default=None,
                    help="another network than the recipe's (demo --network); use another --out")
    ap.add_argument("--networks", choices=NETWORKS, nargs="+", default=None,
                    help="each of these networks, then side by side (OUT/<network>/seed<S>)")
    ap.add_argument("--table-only", action="store_true",
                    help="with --networks: only the side-by-side table, from a former run")
    a = ap.parse_args()
    if a.table_only and not a.networks:
        ap.error("--table-only prints the --networks table: name the networks")
    if a.network and a.networks:
        ap.error("--network or --networks, not both")
    for net in a.networks or [a.network]:
        if a.table_only:
            break
        extra = ("--network", net) if net else ()
        root = a.out / net if a.networks else a.out
        for seed in a.seeds:
            out = root / f"seed{seed}"
            report(out, seed, run_demo(out, seed, a.jobs, extra))
    if a.networks:
        compare(a.out, a.networks, a.seeds)


if __name__ == "__main__":
    main()

"""The scarcity study's transfer learning from the one generic model against the per-fold
protocol's, on the same presses (docs/results.md, "The scarcity study against the per-fold
protocol"), so the gains at few presses can be re-measured like for like.

    python benchmarks/bench_scarcity.py DEMO_OUT [DEMO_OUT ...] [--folds 0 1] \
        [--groups 1 2 3 4] [--fits protocol own] [--epochs N] [--jobs 2] [--out DIR]

A quick demo's scarcity study (``DEMO_OUT/scarcity``) retrains folds on their first 1..n
training presses from scratch and from the generic model. Here the same folds are retrained on
the same presses, with the same options (the demo's TL run's, at the demo's scarcity epochs),
from a model pre-trained per fold on its fitted MSM (``pipeline demo --pretraining per-fold``'s
steps and settings), the fit being either

- ``protocol``: the per-fold protocol's own, on 3 of the fold's training presses drawn with the
  seed, whichever n the run has (at 1 and 2 presses it has seen presses the run has not);
- ``own``: on the run's own n presses (3 of them drawn with the seed where n is more): the
  per-fold protocol with only the lab data the run has, one fit and pre-training per n.

Printed per demo and number of presses: the mean L_d over the folds' test examples (the mean of
the folds' means, as the study's table) of scratch, of TL from the generic model (both the
demo's own runs) and of TL from each per-fold fit, and each TL's gain over scratch; the
no-learning references beside them. ``--epochs`` other than the demo's scarcity epochs trains
every run at that many, scratch and the generic model's TL again too (like for like). Each run
trains on one thread, ``--jobs`` at a time, into
``OUT/<demo>/...`` (a run already there is scored again, not retrained).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

FITS = ("protocol", "own")
RETRAINED = {"scratch": "no TL", "generic": "TL"}   # the demo's own runs, trained again


def pretraining(demo: Path, out: Path, fold: int, fit: str, n: int) -> Path:
    """The fold's per-fold pre-trained model (the demo's per-fold steps, unless already
    there), its MSM fitted as ``fit`` says; its best.pt."""
    from pipeline.demo_plan import QUICK, RECIPE, per_fold_steps, pretrain_dir

    seed = str(json.loads((demo / "splits.json").read_text())["seed"])
    where, fitted = pretrain_place(out, demo, fit, n)
    splits = demo / "splits.json"
    if fit == "own":
        splits = where / f"splits_fold{fold}.json"
        splits.parent.mkdir(parents=True, exist_ok=True)
        splits.write_text(json.dumps(own_presses(demo / "splits.json", fold, n)))
    s = dataclasses.replace(QUICK, folds=fold + 1, fit_sequences=fitted)
    train = ("--device", "cpu", "--lr", str(s.lr), "--batch", str(s.batch), *RECIPE)
    steps = per_fold_steps(where, s, demo / "session_states.h5", splits, train, ("--seed", seed))
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    for step in steps[fold::s.folds]:
        if not all(Path(o).exists() for o in step.outputs):
            subprocess.run(["pipeline", *step.args], check=True, env=env,
                           stdout=subprocess.DEVNULL)
    return pretrain_dir(where, fold) / "best.pt"


def pretrain_place(out: Path, demo: Path, fit: str, n: int) -> tuple[Path, int]:
    """Where a fit's pre-training lives, and how many presses it fits."""
    from pipeline.demo_plan import QUICK

    most = QUICK.fit_sequences
    if fit == "protocol":
        return out / demo.name / "protocol", most
    return out / demo.name / f"own_n{n}", min(n, most)


def own_presses(splits: Path, fold: int, n: int) -> dict:
    """The manifest with fold ``fold``'s training presses cut to its first ``n`` (the
    scarcity run's), so that the fit sees only those."""
    doc = json.loads(splits.read_text())
    f = doc["folds"][fold]
    f["train"]["groups"] = f["train_subsets"][n - 1]
    f["train_subsets"] = f["train_subsets"][:n]
    return doc


def fine_tune(job: tuple[Path, Path, int, str, int, int]) -> float:
    """One scarcity run (``kind``: a per-fold fit's pre-trained model, or one of
    :data:`RETRAINED`) at ``epochs``: trained unless there; its mean L_d (mm) on the fold's
    test examples."""
    import torch

    torch.set_num_threads(1)
    from pipeline.demo_plan import QUICK
    from train.evaluation.run_errors import example_errors, load_run
    from train.evaluation.scarcity import Retraining
    from train.evaluation.scoring import metrics

    demo, out, fold, kind, n, epochs = job
    again = Retraining.of(demo / "runs" / f"exp_tl_fold{fold}", epochs)
    init = {"scratch": None, "generic": again.init}[kind] if kind in RETRAINED \
        else pretraining(demo, out, fold, kind, n)
    run = out / demo.name / (f"{kind}_f{fold}_n{n:02d}"
                             + ("" if epochs == QUICK.scarcity_epochs else f"_e{epochs}"))
    loaded = load_run(run, "cpu") if (run / "best.pt").is_file() \
        else again.train(n, init, run, "cpu")
    return metrics(example_errors(loaded)[0]).all.ld_mean_mm


def study_rows(demo: Path, folds: list[int]) -> dict[tuple[str, int, int], float]:
    """The demo's own scarcity rows: (predictor, fold, presses) -> mean L_d (mm)."""
    from pipeline.demo_targets import scarcity_rows

    return {(r.predictor, r.fold, r.groups): r.ld_mean_mm for r in scarcity_rows(demo)
            if r.fold in folds and r.ld_mean_mm is not None}


def table(demo: Path, folds: list[int], groups: list[int], fits: list[str],
          done: dict[tuple[str, int, int], float]) -> None:
    """Per number of presses: each predictor's mean over folds, and each TL's gain."""
    rows = study_rows(demo, folds) | done
    names = ["no TL", "TL", *(f"TL, per-fold fit: {f}" for f in fits),
             "nothing moves", "nearest press"]

    def mean(name: str, n: int) -> float:
        return sum(rows[(name, f, n)] for f in folds) / len(folds)

    print(f"\n{demo} (folds {', '.join(map(str, folds))}): mean L_d, mm (TL's gain over "
          "scratch)")
    print("| presses | " + " | ".join(names) + " |")
    print("|---" * (len(names) + 1) + "|")
    for n in groups:
        cells = [f"{mean(name, n):.4f}" + (f" ({1 - mean(name, n) / mean('no TL', n):+.1%})"
                                           if name.startswith("TL") else "")
                 for name in names]
        print(f"| {n} | " + " | ".join(cells) + " |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("demos", nargs="+", type=Path)
    ap.add_argument("--folds", nargs="+", type=int, default=[0, 1])
    ap.add_argument("--groups", nargs="+", type=int, default=[1, 2, 3, 4])
    ap.add_argument("--fits", nargs="+", choices=FITS, default=list(FITS))
    ap.add_argument("--epochs", type=int, default=None,
                    help="every run's epochs (default: the quick demo's scarcity epochs)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("/tmp/bench_scarcity"))
    a = ap.parse_args()
    from pipeline.demo_plan import QUICK

    epochs = a.epochs or QUICK.scarcity_epochs
    kinds = a.fits + ([] if epochs == QUICK.scarcity_epochs else list(RETRAINED))
    shared = [(d, a.out, f, "protocol", 0) for d in a.demos for f in a.folds] \
        if "protocol" in a.fits else []
    jobs = [(d, a.out, f, kind, n, epochs) for d in a.demos for kind in kinds
            for n in a.groups for f in a.folds]
    with ProcessPoolExecutor(a.jobs) as pool:
        if shared:                  # one pre-training per fold, before the runs that share it
            list(pool.map(pretraining, *zip(*shared, strict=True)))
        done = dict(zip(jobs, pool.map(fine_tune, jobs), strict=True))
    for d in a.demos:
        table(d, a.folds, a.groups, a.fits,
              {(RETRAINED.get(kind, f"TL, per-fold fit: {kind}"), f, n): ld
               for (demo, _, f, kind, n, _), ld in done.items() if demo == d})


if __name__ == "__main__":
    main()

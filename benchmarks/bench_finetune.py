"""Fine-tuning's epochs against accuracy: each fold of quick demos fine-tuned again with other
settings, from the demo's own per-fold pre-trained model (docs/results.md, "Fine-tuning
longer"), so the trade of minutes against pooled L_d can be re-measured.

    python benchmarks/bench_finetune.py DEMO_OUT [DEMO_OUT ...] [--settings tl:80 tl:160 \
        tl:240 tl:160:cosine scratch:160] [--init GENERIC.pt] [--jobs 2] [--out DIR]

A setting is ``tl`` (from the fold's ``runs/msm_foldK/best.pt``) or ``scratch`` (random
weights), the epochs, and optionally the schedule, the step size (``lr1e-3``), the batch
(``bs64``) and ``preN``: pre-train the fold's MSM run
again for N epochs (``preN-cosine``: with that schedule; its own options otherwise; beside the
fine-tuning run, its minutes counted in the setting's) and fine-tune from that
(``tl:80:pre40``); everything else is the demo's own TL run's options
(``runs/exp_tl_foldK/best.pt``: the recipe, its seed, its fold). ``--init`` starts every ``tl``
setting from that checkpoint instead (one pre-training for every fold and lab: the generic
model, docs/model.md); with ``preN`` the fold's MSM run starts from it (the generic model
adapted to the fold's fitted MSM for N epochs, then fine-tuned). Each run trains on one thread,
``--jobs`` at a time (a run is one fold's fine-tuning), into ``OUT/<demo>/<setting>_fK`` (a run
already there is scored again, not retrained). Printed: per demo and setting the pooled mean
L_d over the folds' test examples (weighted by their count), each fold's, and the mean minutes
of the fold runs beside it; first the demo's own TL and scratch runs, as they are, and the
no-learning references on the same examples (fitted on each fold's training presses).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

FOLDS = 5


def fine_tune(job: tuple[Path, int, str, Path, Path | None]) -> dict:
    """One fold's run of one setting (trained unless its best.pt exists), scored on the fold's
    test examples."""
    import torch

    torch.set_num_threads(1)
    from train.evaluation.run_errors import test_errors
    from train.evaluation.scoring import metrics

    demo, fold, setting, run, generic = job
    start, tune, pre = parse(setting)
    tic = time.perf_counter()
    init = generic or demo / "runs" / f"msm_fold{fold}" / "best.pt"
    if pre:
        init = trained(demo / "runs" / f"msm_fold{fold}", run.with_name(run.name + "_pre"), pre,
                       generic)
    trained(demo / "runs" / f"exp_tl_fold{fold}", run, tune, init if start == "tl" else None)
    return score(run, time.perf_counter() - tic, metrics, test_errors)


SCHEDULES = ("constant", "cosine")


def parse(setting: str) -> tuple[str, dict, dict | None]:
    """A setting's start (tl or scratch), its fine-tuning's option changes, and its
    pre-training's (None: the demo's own pre-trained model); ValueError for a malformed one,
    caught before any run starts."""
    start, *parts = setting.split(":")
    epochs, rest = (parts[0] if parts else ""), parts[1:]
    pre = [r[3:] for r in rest if r.startswith("pre")]
    lr = [float(r[2:]) for r in rest if r.startswith("lr")]
    batch = [int(r[2:]) for r in rest if r.startswith("bs")]
    schedule = [r for r in rest if not r.startswith(("pre", "lr", "bs"))]
    if start not in ("tl", "scratch") or max(len(pre), len(lr), len(batch), len(schedule)) > 1 \
            or (pre and start == "scratch"):
        raise ValueError(f"setting {setting!r}: tl|scratch:EPOCHS[:SCHEDULE][:lrRATE][:bsBATCH]"
                         "[:preN[-SCHEDULE]] (preN only with tl)")
    tune = {**changes(epochs, *schedule), **({"lr": lr[0]} if lr else {}),
            **({"batch": batch[0]} if batch else {})}
    return start, tune, changes(*pre[0].split("-", 1)) if pre else None


def changes(epochs: str, schedule: str | None = None) -> dict:
    """The options a part of a setting changes: the epochs, and the schedule where it names
    one (ValueError for epochs that are not a positive whole number, or another schedule)."""
    if not epochs.isdigit() or int(epochs) < 1 or schedule not in (None, *SCHEDULES):
        raise ValueError(f"epochs {epochs!r} and schedule {schedule!r}: a positive whole "
                         f"number, and one of {', '.join(SCHEDULES)}")
    return {"epochs": int(epochs), **({"schedule": schedule} if schedule else {})}


def trained(like: Path, run: Path, edits: dict, init: Path | None = None) -> Path:
    """``run``'s best.pt: the run ``like`` trained again (unless already there) with
    ``edits`` to its options, from ``init`` (None: random weights)."""
    from train.model.config import CGNNConfig
    from train.training.checkpoint import load_checkpoint
    from train.training.train_params import TrainInputs, TrainOptions, TrainParams
    from train.training.train_stage import run_train

    meta = load_checkpoint(like / "best.pt")["meta"]
    if not (run / "best.pt").is_file():
        opts = dataclasses.replace(TrainOptions(**meta["options"]), **edits)
        run_train(TrainInputs(Path(meta["data"]["file"]), Path(meta["splits"]), init), run,
                  TrainParams(opts, CGNNConfig.from_dict(meta["config"]), "cpu"))
    return run / "best.pt"


def score(run: Path, seconds: float, metrics, test_errors) -> dict:
    """A run's test examples' count and mean L_d (mm), and the seconds it took."""
    m = metrics(test_errors(run)[0]).all
    return {"n": m.n, "ld": m.ld_mean_mm, "seconds": seconds}


def references(demo: Path) -> dict[str, list[dict]]:
    """Each no-learning reference's rows on the folds' test examples, fitted on each fold's
    training presses (the demo's TL runs name the folds): what every setting must beat."""
    from train.evaluation.run_errors import load_run, reference_errors
    from train.evaluation.scoring import metrics

    rows: dict[str, list[dict]] = {}
    for f in range(FOLDS):
        for name, errs in reference_errors(load_run(demo / "runs" / f"exp_tl_fold{f}")).items():
            m = metrics(errs).all
            if m.ld_mean_mm is not None:          # the force's reference moves no point
                rows.setdefault(name, []).append({"n": m.n, "ld": m.ld_mean_mm,
                                                  "seconds": 0.0})
    return rows


def line(name: str, rows: list[dict], timed: bool = True) -> str:
    """One setting's row: pooled L_d, each fold's, the mean minutes of a fold run."""
    pooled = sum(r["ld"] * r["n"] for r in rows) / sum(r["n"] for r in rows)
    folds = " ".join(f"{r['ld']:.3f}" for r in rows)
    minutes = f"{sum(r['seconds'] for r in rows) / len(rows) / 60:.2f}" if timed else "–"
    return f"| {name} | {pooled:.4f} mm | {folds} | {minutes} |"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("demos", nargs="+", type=Path)
    ap.add_argument("--settings", nargs="+", default=["tl:160", "tl:240", "scratch:160"])
    ap.add_argument("--init", type=Path, default=None,
                    help="tl settings start from this checkpoint (a generic model)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("/tmp/bench_finetune"))
    a = ap.parse_args()
    try:
        for setting in a.settings:
            parse(setting)
    except ValueError as e:
        ap.error(str(e))
    from train.evaluation.run_errors import test_errors
    from train.evaluation.scoring import metrics

    jobs = [(d, f, s, a.out / d.name / f"{s.replace(':', '_')}_f{f}", a.init)
            for d in a.demos for s in a.settings for f in range(FOLDS)]
    with ProcessPoolExecutor(a.jobs) as pool:
        done = {(d, s, f): row for (d, f, s, _, _), row in
                zip(jobs, pool.map(fine_tune, jobs), strict=True)}
    print("| demo, setting | pooled mean L_d | per fold | minutes a fold run |")
    print("|---|---|---|---|")
    for d in a.demos:
        for kind, name in (("tl", "TL"), ("notl", "scratch")):
            own = [score(d / "runs" / f"exp_{kind}_fold{f}", 0.0, metrics, test_errors)
                   for f in range(FOLDS)]
            print(line(f"{d.name}, the demo's {name}", own, timed=False))
        for name, rows in references(d).items():
            print(line(f"{d.name}, reference: {name}", rows, timed=False))
        for s in a.settings:
            print(line(f"{d.name}, {s}", [done[(d, s, f)] for f in range(FOLDS)]))

if __name__ == "__main__":
    main()

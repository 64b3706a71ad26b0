"""How sure the model is: the conformal intervals beside a deep ensemble's, on the quick demo's
folds, and what the intervals cost a prediction (docs/results.md, "How sure the model is").

    python benchmarks/bench_intervals.py DEMO_OUT [--folds 0 1 2 3 4] [--members 4] [--variant tl]
    python benchmarks/bench_intervals.py --latency
    python benchmarks/bench_intervals.py DEMO_OUT --misses [--variant tl notl solid]

``DEMO_OUT`` is a ``pipeline demo --quick`` folder. Per fold, the run ``runs/exp_<variant>_foldK``
(its best.pt keeps the conformal table, calibrated on the fold's validation presses) and
``members - 1`` more runs trained like it (the same training presses, the same --init, other
seeds; into ``DEMO_OUT/ensemble/``, kept for a second run) make the ensemble. Never the other
folds' models: they trained on this fold's test presses. The ensemble's answer is its members'
mean; its interval is their spread scaled on the same validation presses (normalised split
conformal: a point's radius is q x its members' RMS distance from their mean, q the
``ceil((n + 1) level)``-th smallest error / spread over the calibration points; the force
alike). Printed per fold and pooled, at 80, 90 and 95 %: the share of test points inside
their radius and the mean radius, the same for the force, for both.

``--misses``: where the force's 90 % interval misses on the folds' test presses (pooled over
the folds): by the example's end force (thirds), by place (the states' location), and the
share the fold's stored tables would cover on average had their calibration presses been
drawn at random among the fold's held-out presses (the same number, 100 draws a fold): a
rule calibrated on average whose share still falls short was dealt hard test presses.

``--latency``: the predictor's batch-1 latency on a known mesh (26 and 1024 points, ONNX
Runtime, head offsets) with and without ``level=0.9``, the press repeated and a moving tip,
median of many calls in alternating blocks.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from data_schema.intervals_doc import IntervalLevel  # noqa: E402
from train.data import (  # noqa: E402
    SETS,
    example_groups,
    example_pairs,
    load_manifest,
    make_batch,
    role_examples,
)
from train.evaluation.coverage import coverage, coverage_doc  # noqa: E402
from train.evaluation.coverage_band import redrawn_counts  # noqa: E402
from train.evaluation.run_errors import LoadedRun, load_run  # noqa: E402
from train.intervals.levels import REPORTED, level_index  # noqa: E402
from train.intervals.quantiles import conformal_quantile  # noqa: E402
from train.model.config import CGNNConfig  # noqa: E402
from train.model.si_units import distances, predict  # noqa: E402
from train.training.calibrate import Residuals, joined, residuals  # noqa: E402
from train.training.checkpoint import load_checkpoint  # noqa: E402
from train.training.train_params import TrainInputs, TrainOptions, TrainParams  # noqa: E402
from train.training.train_stage import run_train  # noqa: E402


def members(run_dir: Path, out: Path, count: int) -> list[LoadedRun]:
    """The run and ``count - 1`` more trained like it with seeds 1.., loaded."""
    meta = load_checkpoint(run_dir / "best.pt")["meta"]
    opts, config = TrainOptions.from_dict(meta["options"]), CGNNConfig.from_dict(meta["config"])
    inputs = TrainInputs(Path(meta["data"]["file"]), Path(meta["splits"]),
                         Path(meta["init"]) if meta["init"] else None)
    dirs = [run_dir]
    for seed in range(opts.seed + 1, opts.seed + count):
        d = out / f"{run_dir.name}_seed{seed}"
        if not (d / "best.pt").is_file():
            run_train(inputs, d, TrainParams(dataclasses.replace(opts, seed=seed), config, "cpu"))
        dirs.append(d)
    return [load_run(d) for d in dirs]


@torch.no_grad()
def spread(runs: list[LoadedRun], role_pairs: torch.Tensor) -> dict[str, np.ndarray]:
    """The ensemble on examples ``role_pairs``: per valid point its mean's error and the
    members' RMS distance from their mean; per example the same for the force."""
    first = runs[0]
    out: dict[str, list] = {"err": [], "sd": [], "ferr": [], "fsd": []}
    for rows in role_pairs.split(64):
        b = make_batch(first.states, rows)
        preds = [predict(r.model, r.norm, b) for r in runs]
        pts = torch.stack([p.deformed for p in preds])                 # (M, B, N, 3)
        force = torch.stack([p.dforce for p in preds])                 # (M, B)
        mean = pts.mean(0)
        sd = ((pts - mean) ** 2).sum(-1).mean(0).sqrt()                 # (B, N)
        err = distances(type(preds[0])(mean, force.mean(0)), b)
        mask = b.mask
        out["err"].append(err[mask].double().numpy())
        out["sd"].append(sd[mask].double().numpy())
        out["ferr"].append((force.mean(0) - b.dforce).abs().double().numpy())
        out["fsd"].append(force.std(0, unbiased=False).double().numpy())
    return {k: np.concatenate(v) for k, v in out.items()}


def ensemble_rows(cal: dict[str, np.ndarray], test: dict[str, np.ndarray]
                  ) -> list[IntervalLevel]:
    """Per reported level: the test share inside and mean width of the ensemble's spread
    scaled on the calibration (points, force)."""
    rows = []
    for level in REPORTED:
        q = conformal_quantile(cal["err"] / np.maximum(cal["sd"], 1e-12), np.array([level]))[0]
        qf = conformal_quantile(cal["ferr"] / np.maximum(cal["fsd"], 1e-12),
                                np.array([level]))[0]
        radius, half = q * test["sd"], qf * test["fsd"]
        rows.append(IntervalLevel(level=level, points=len(radius),
                                  coverage=float((test["err"] <= radius).mean()),
                                  mean_radius_mm=float(radius.mean() * 1e3), examples=len(half),
                                  force_coverage=float((test["ferr"] <= half).mean()),
                                  force_half_width_n=float(half.mean())))
    return rows


def fold_rows(run_dir: Path, out: Path, count: int
              ) -> tuple[list[IntervalLevel], list[IntervalLevel], dict]:
    """Conformal (the run's own table) and ensemble rows on the run's test presses, and the
    raw spreads (to pool)."""
    runs = members(run_dir, out, count)
    first = runs[0]
    meta = first.meta
    doc = load_manifest(Path(meta["splits"]), Path(meta["data"]["file"]))
    val = example_pairs(first.states, role_examples(doc, meta["options"]["fold"], "val"))
    test = example_pairs(first.states, first.test)
    conf = coverage(first.intervals, residuals(first.model, first.norm, first.states, test))
    cal, tst = spread(runs, val), spread(runs, test)
    return coverage_doc(conf, None).levels, ensemble_rows(cal, tst), {"cal": cal, "test": tst,
                                                                       "conf": conf}


def show(name: str, conf: list[IntervalLevel], ens: list[IntervalLevel]) -> None:
    for c, e in zip(conf, ens, strict=True):
        print(f"| {name} | {c.level:.0%} | {c.coverage:.1%} / {c.mean_radius_mm:.3f} mm"
              f" | {e.coverage:.1%} / {e.mean_radius_mm:.3f} mm | "
              f"{c.force_coverage:.1%} / {c.force_half_width_n:.3f} N | "
              f"{e.force_coverage:.1%} / {e.force_half_width_n:.3f} N |")


def compare(demo: Path, folds: list[int], count: int, variant: str) -> None:
    print(f"| fold | level | conformal points: inside / mean radius | ensemble ({count}) points "
          "| conformal force: inside / half-width | ensemble force |")
    print("|---|---|---|---|---|---|")
    pooled_cal: dict[str, list] = {}
    pooled_test: dict[str, list] = {}
    conf_sum = None
    for fold in folds:
        tic = time.perf_counter()
        conf, ens, raw = fold_rows(demo / "runs" / f"exp_{variant}_fold{fold}",
                                   demo / "ensemble", count)
        show(str(fold), conf, ens)
        print(f"<!-- fold {fold}: {time.perf_counter() - tic:.0f} s -->", flush=True)
        conf_sum = raw["conf"] if conf_sum is None else conf_sum + raw["conf"]
        for k, v in raw["cal"].items():
            pooled_cal.setdefault(k, []).append(v)
        for k, v in raw["test"].items():
            pooled_test.setdefault(k, []).append(v)
    # pooled: each fold scaled on its own calibration, so pool the per-fold rows' counts
    show("pooled conformal / fold-mean ensemble", coverage_doc(conf_sum, None).levels,
         _mean_rows([ensemble_rows({k: v[i] for k, v in pooled_cal.items()},
                                   {k: v[i] for k, v in pooled_test.items()})
                     for i in range(len(folds))],
                    [len(t) for t in pooled_test["err"]], [len(t) for t in pooled_test["ferr"]]))


def _mean_rows(per_fold: list[list[IntervalLevel]], points: list[int], examples: list[int]
               ) -> list[IntervalLevel]:
    """Per level, the folds' rows weighted by their test points (force: examples)."""
    out = []
    for k in range(len(REPORTED)):
        rows = [f[k] for f in per_fold]
        wp, we = np.array(points, float), np.array(examples, float)

        def mean(value, weights: np.ndarray, rows: list[IntervalLevel] = rows) -> float:
            return float(np.average([value(r) for r in rows], weights=weights))

        out.append(dataclasses.replace(
            rows[0], points=sum(points), examples=sum(examples),
            coverage=mean(lambda r: r.coverage, wp),
            mean_radius_mm=mean(lambda r: r.mean_radius_mm, wp),
            force_coverage=mean(lambda r: r.force_coverage, we),
            force_half_width_n=mean(lambda r: r.force_half_width_n, we)))
    return out


def held_out(run: LoadedRun) -> tuple[Residuals, np.ndarray, np.ndarray, np.ndarray]:
    """A run's residuals on its validation then test examples, each example's press and end
    state, and which are test examples."""
    doc = load_manifest(run.splits, Path(run.meta["data"]["file"]))
    groups = example_groups(run.meta["data"]["file"], doc["group_by"])
    roles = (role_examples(doc, run.meta["options"]["fold"], "val"), run.test)
    pairs = [example_pairs(run.states, ids) for ids in roles]
    r = joined([residuals(run.model, run.norm, run.states, p) for p in pairs])
    press = np.concatenate([groups[s][ids[s]] for ids in roles for s in SETS])
    test = np.repeat([False, True], [len(p) for p in pairs])
    return r, press, torch.cat(pairs)[:, 1].numpy(), test


def misses(demo: Path, folds: list[int], variant: str, level: float = 0.9) -> None:
    """Where the force's ``level`` interval (one of REPORTED) misses on the test presses,
    pooled over ``folds`` (by end force in thirds and by place), and its share with re-drawn
    calibration presses (:func:`~train.evaluation.coverage_band.redrawn_counts`)."""
    i, shown = level_index(level), REPORTED.index(level)
    miss, force, place, drawn = [], [], [], np.zeros(2)
    for fold in folds:
        run = load_run(demo / "runs" / f"exp_{variant}_fold{fold}")
        r, press, end, test = held_out(run)
        half = run.intervals.force.widths(i, *r.force_features[test].T)
        miss.append(np.abs(r.force_error[test]) > half)
        force.append(run.states.force.numpy()[end[test]])
        place.append(np.asarray(run.states.location)[end[test]])
        counts = redrawn_counts(r, press, run.intervals.presses, fold, draws=100)
        if counts is not None:                 # None: no press left to score
            drawn += counts[:, shown, 2:].sum(0)
    miss, force, place = (np.concatenate(v) for v in (miss, force, place))
    thirds = np.searchsorted(np.quantile(force, [1 / 3, 2 / 3]), force)
    print(f"{variant}: force {level:.0%} interval misses {miss.mean():.1%} of {len(miss)} test "
          f"examples; with the calibration presses re-drawn {1 - drawn[0] / drawn[1]:.1%}")
    cut = [thirds == k for k in range(3)]
    print("  by end force, thirds: " + ", ".join(
        f"{force[k].min():.1f}-{force[k].max():.1f} N {miss[k].mean():.1%}" for k in cut))
    at = [place == p for p in np.unique(place)]
    print("  by place: " + ", ".join(f"{int(place[k][0])} {miss[k].mean():.1%} ({k.sum()})"
                                    for k in at))


def latency(repeats: int = 3000) -> None:
    """Known-mesh batch-1 latency with and without intervals: bench_cgnn.py's surfaces, press
    and head-offset network (ONNX Runtime), a table of 24 point bins and 4 force bins; the
    press repeated, and a moving tip (its end descending 10 um a call); with and without in
    alternating blocks, median of every call."""
    from bench_cgnn import NETWORKS, NORM, PRESS, surface

    from train import Predictor
    from train.inference.si_model import SIModel
    from train.intervals.table import IntervalTable
    from train.model.cgnn import CGNN

    rng = np.random.default_rng(0)
    table = IntervalTable.fit(rng.exponential(1e-4, 4000), rng.uniform(0, 0.05, (4000, 3)),
                              rng.exponential(0.1, 400), rng.uniform(0, 0.01, (400, 2)), 3)
    torch.manual_seed(0)
    pred = Predictor(SIModel(CGNN(NETWORKS["head offsets"]).eval(), NORM), torch.device("cpu"),
                     "onnx")
    pred.intervals = table
    press = np.asarray(PRESS, np.float32).reshape(-1)
    moving = [np.r_[press[:5], press[5] + 1e-3 - 1e-5 * k].astype(np.float32)
              for k in range(200)]
    print("known-mesh batch-1 latency, head offsets, ONNX Runtime [ms] (median):")
    for n in (26, 1024):
        pts = surface(n, False)
        reps = max(30, repeats * 26 // n // 20)
        for name, conds in (("repeated press", [press]), ("moving tip", moving)):
            times: dict[bool, list[float]] = {False: [], True: []}
            for block in range(20):
                for sure in (False, True) if block % 2 else (True, False):
                    kw = {"level": 0.9} if sure else {}
                    for k in range(reps):
                        c = conds[k % len(conds)]
                        tic = time.perf_counter()
                        pred.predict(pts, c, **kw)
                        times[sure].append(time.perf_counter() - tic)
            plain, with_ = (float(np.median(times[k])) * 1e3 for k in (False, True))
            print(f"  N={n:5d} {name:14s} without {plain:.4f}  with level=0.9 {with_:.4f}  "
                  f"(+{with_ / plain - 1:.0%})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("demo", nargs="?", type=Path)
    ap.add_argument("--folds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--members", type=int, default=4)
    ap.add_argument("--variant", choices=("tl", "notl", "solid"), nargs="+", default=["tl"])
    ap.add_argument("--latency", action="store_true")
    ap.add_argument("--misses", action="store_true")
    a = ap.parse_args()
    torch.set_num_threads(1)
    if a.latency:
        latency()
    if a.demo is not None and a.misses:
        for variant in a.variant:
            misses(a.demo, a.folds, variant)
    elif a.demo is not None:
        compare(a.demo, a.folds, a.members, a.variant[0])


if __name__ == "__main__":
    main()

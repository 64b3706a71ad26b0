"""The speed-accuracy report: what each cGNN setting costs and what it buys, on the same data.

Every row is measured in one run on one machine, on the same test examples:
- k (3, 5, 10, 20), the fraction of points per training sample (1 .. 0.25) and rotation
  augmentation: cGNN/Exp runs on fold 0 of a twin session (26 points), same epochs and seed;
- precision: the k = 5 model in float32, float64 and bfloat16 autocast (where the device has it);
- number of points: batch-1 latency at 26 .. 4096 points; accuracy of an MSM-trained model on
  its test surfaces resampled to 26 .. all of the grid's points;
- robustness: the twin test set turned 90 degrees about the surface normal, tilted 10 and 30
  degrees, and with a quarter or half of its markers left out, for the plain model and the one
  trained with rotation augmentation (errors and their ratio to the unmoved test set);
- region of interest: ``Predictor.predict(..., region=R)`` for R from 5 mm to the whole surface
  at 1024 and 4096 points, errors against truth and the whole model, latency
  (``region_study.py``), with each size's Pareto front and the default radius;
- at the extremes: frame offsets, press sizes, depth beyond the phantom and point orders
  through ``train.Predictor`` (``extremes.py``), with what it flagged or refused;
- the MSM fast path's solver tolerance against accuracy and time (``bench_msm.trade_rows``);
- a Pareto table (latency against error) and the setting to pick for a 1 kHz haptic loop
  (force only, one press at 26 points on a mesh pressed again, through ``train.Predictor``:
  a press-independent network runs its force head alone) and for 60 Hz visuals
  (displacements of 1024 points).

Writes ``OUT/report.md``, ``OUT/results.json`` and PNG plots; runs and data are kept under OUT
so a second call only re-measures (delete OUT/runs to retrain).

    python benchmarks/speed_accuracy.py --out out/speed_accuracy --quick   (~12 min, 2 cores)
    python benchmarks/speed_accuracy.py --out out/speed_accuracy           (paper epochs, GPU)
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch
from bench_cgnn import median_ms
from bench_msm import trade_rows
from extremes import extreme_rows
from region_study import region_rows
from speed_accuracy_report import write_report

from core.progress import set_quiet
from sim.msm.msm import MSMParams
from sim.msm.msm_protocol import Protocol
from sim.msm.simulate_stage import generate
from train.data import Batch
from train.evaluation.run_errors import LoadedRun, example_errors, load_run
from train.evaluation.scoring import metrics
from train.inference.predictor import Predictor
from train.inference.si_model import SIModel
from train.model.cgnn import CGNN
from train.model.config import CGNNConfig
from train.model.si_units import BatchPrediction, predict
from train.training.augment import about_normal, move_batch, tilt
from train.training.train_params import TrainInputs, TrainOptions, TrainParams
from train.training.train_stage import run_train

HAPTIC_MS = 1.0          # a 1 kHz haptic loop's whole budget
VISUAL_MS = 1000 / 60    # one 60 Hz frame
POINT_COUNTS = (26, 64, 256, 1024, 4096)


@dataclass(frozen=True)
class Budget:
    """How long to train: --quick fits 2 CPU cores in minutes, the default follows the paper."""

    twin_epochs: int
    msm_epochs: int
    msm_grid: int
    msm_locations: int
    msm_directions: int
    lr: float
    repeats: int
    region_epochs: int


QUICK = Budget(twin_epochs=80, msm_epochs=15, msm_grid=16, msm_locations=12,
               msm_directions=3, lr=1e-3, repeats=50, region_epochs=15)
PAPER = Budget(twin_epochs=250, msm_epochs=100, msm_grid=32, msm_locations=100,
               msm_directions=11, lr=1e-4, repeats=200, region_epochs=100)


def pipeline(*args: str) -> None:
    """Run one pipeline command (quiet, no recording); stop the report if it fails."""
    subprocess.run([sys.executable, "-m", "pipeline", "-q", *args], check=True)


def twin_data(out: Path, given: Path | None, seed: int) -> tuple[Path, Path]:
    """States and fold manifest of a twin session: ``given`` (a demo folder) or made here."""
    if given is not None:
        return given / "session_states.h5", given / "splits.json"
    d = out / "data"
    states, splits = d / "states.h5", d / "splits.json"
    if not splits.is_file():
        d.mkdir(parents=True, exist_ok=True)
        pipeline("synth", str(d / "session"), "--seed", str(seed), "--no-rrd")
        pipeline("ingest", str(d / "session"), "--out", str(d / "session.mcap"), "--no-rrd")
        pipeline("sync", str(d / "session.mcap"), "--out", str(d / "synced.h5"), "--no-rrd")
        pipeline("extract", str(d / "synced.h5"), "--out", str(states), "--seed", str(seed),
                 "--no-rrd")
        pipeline("split", str(states), "--out", str(splits), "--seed", str(seed), "--no-rrd")
    return states, splits


def msm_data(out: Path, budget: Budget, seed: int) -> tuple[Path, Path]:
    """An MSM set on a ``msm_grid`` x ``msm_grid`` surface, split 7:2:1 by location."""
    d = out / "data"
    states, splits = d / f"msm{budget.msm_grid}.h5", d / f"msm{budget.msm_grid}_splits.json"
    if not splits.is_file():
        d.mkdir(parents=True, exist_ok=True)
        generate(states, Protocol(locations=budget.msm_locations,
                                  directions=budget.msm_directions),
                 MSMParams(n=budget.msm_grid), workers=min(2, os.cpu_count() or 1))
        pipeline("split", str(states), "--out", str(splits), "--folds", "1", "--seed",
                 str(seed), "--no-rrd")
    return states, splits


def trained(out: Path, name: str, data: tuple[Path, Path], epochs: int, budget: Budget,
            device: str, seed: int, k: int = 5, **options: object) -> LoadedRun:
    """Train (or resume, or reuse) one setting on fold 0; its best model, loaded."""
    run_dir = out / "runs" / name
    opts = TrainOptions(fold=0, epochs=epochs, lr=budget.lr, seed=seed, **options)
    tic = time.perf_counter()
    run_train(TrainInputs(data[0], data[1]), run_dir, TrainParams(opts, CGNNConfig(k=k), device))
    print(f"  trained {name} ({epochs} epochs) in {time.perf_counter() - tic:.0f} s",
          flush=True)
    return load_run(run_dir, device)


def train_seconds_per_epoch(name: str, out: Path) -> float:
    """Median seconds of a training epoch, from the run's log."""
    with open(out / "runs" / name / "log.csv") as f:
        rows = f.read().splitlines()[1:]
    return float(np.median([float(r.split(",")[5]) for r in rows]))


def accuracy(run: LoadedRun, transform: Callable[[Batch], Batch] | None = None,
             predictor: Callable[[Batch], BatchPrediction] | None = None) -> dict[str, float]:
    """Mean L_d, mean max L_d (mm) and force absolute error (N) on the fold's test set."""
    m = metrics(example_errors(run, transform, predictor)[0]).all
    return {"ld_mm": m.ld_mean_mm, "ld_max_mm": m.ld_max_mm, "force_n": m.force_abs_n}


def latency(model: CGNN, n: int, device: torch.device, repeats: int, force_only: bool = False,
            dtype: torch.dtype = torch.float32, autocast: bool = False) -> float:
    """Median batch-1 milliseconds at ``n`` points (random points: the graph is rebuilt)."""
    p = torch.rand(1, n, 3, device=device, dtype=dtype)
    c = torch.rand(1, 6, device=device, dtype=dtype)
    fn = model.forward_force if force_only else model
    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)

    def call() -> object:
        with torch.autocast(device.type, torch.bfloat16, enabled=autocast):
            return fn(p, c)

    with torch.inference_mode():
        return median_ms(call, repeats, sync)


def known_mesh_force_ms(run: LoadedRun, model: CGNN, repeats: int) -> float:
    """Median ms of ``Predictor.predict_force`` at 26 points on a mesh pressed again (what a
    haptic loop calls: a press-independent network runs its force head alone), float32,
    the predictor's default backend (ONNX Runtime on a CPU where installed)."""
    device = next(model.parameters()).device
    predictor = Predictor(SIModel(model, run.norm), device)
    pts = run.states.points[0][run.states.valid[0]].cpu().numpy()   # a surface, metres
    start = run.states.tip[0].cpu().numpy()
    press = np.r_[start, start - [0.0, 0.0, 2e-3]].astype(np.float32)   # 2 mm down
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")                         # extrapolation flags: timing
        return median_ms(lambda: predictor.predict_force(pts, press), repeats, lambda: None)


def speed(run: LoadedRun, device: torch.device, repeats: int, model: CGNN | None = None,
          **kw: object) -> dict[str, float]:
    """Latency of the whole network on a new mesh at 26 and 1024 points, and for a float32
    model (no ``kw``) of one press at 26 points, force only, on a known mesh through the
    predictor (the haptic loop: a float64 or autocast model has no such path, so no such
    figure). ``model``: the run's, or a cast copy."""
    model = model or run.model
    out = {"full26_ms": latency(model, 26, device, repeats, **kw),
           "full1024_ms": latency(model, 1024, device, max(5, repeats // 5), **kw)}
    if not kw:                  # the haptic path: float32 through the predictor only
        out["force26_ms"] = known_mesh_force_ms(run, model, repeats)
    return out


def k_rows(out: Path, twin: tuple[Path, Path], b: Budget, dev: str, seed: int) -> list[dict]:
    """Accuracy and latency as k varies."""
    rows = []
    for k in (3, 5, 10, 20):
        run = trained(out, f"twin_k{k}", twin, b.twin_epochs, b, dev, seed, k=k)
        rows.append({"setting": f"k={k}", "k": k, **accuracy(run),
                     **speed(run, torch.device(dev), b.repeats)})
    return rows


def fraction_rows(out: Path, twin: tuple[Path, Path], b: Budget, dev: str, seed: int
                  ) -> list[dict]:
    """Accuracy and training time as the fraction of points per training sample varies."""
    rows = []
    for frac in (1.0, 0.75, 0.5, 0.25):
        name = "twin_k5" if frac == 1.0 else f"twin_frac{frac:g}"
        run = trained(out, name, twin, b.twin_epochs, b, dev, seed,
                      point_fraction=None if frac == 1.0 else frac)
        rows.append({"setting": f"point fraction {frac:g}", "fraction": frac, **accuracy(run),
                     "epoch_s": train_seconds_per_epoch(name, out)})
    return rows


def model_in(run: LoadedRun, dtype: torch.dtype) -> CGNN:
    """A copy of the run's model in ``dtype``."""
    model = CGNN(run.model.config).to(run.states.points.device)
    model.load_state_dict(run.model.state_dict())
    return model.to(dtype).eval()


def cast_predictor(model: CGNN, run: LoadedRun) -> Callable[[Batch], BatchPrediction]:
    """Predict with ``model`` in its precision (inputs cast, outputs back to float32)."""
    dtype = next(model.parameters()).dtype

    def fn(b: Batch) -> BatchPrediction:
        cast = Batch(*(t.to(dtype) if t.is_floating_point() else t for t in
                       (b.points, b.target, b.mask, b.cond, b.dforce)))
        p = predict(model, run.norm, cast)
        return BatchPrediction(p.deformed.float(), p.dforce.float())

    return fn


def autocast_predictor(run: LoadedRun) -> Callable[[Batch], BatchPrediction]:
    """Predict under bfloat16 autocast (matrix products in bfloat16, sums in float32)."""
    device = run.states.points.device.type

    def fn(b: Batch) -> BatchPrediction:
        with torch.autocast(device, torch.bfloat16):
            p = predict(run.model, run.norm, b)
        return BatchPrediction(p.deformed.float(), p.dforce.float())

    return fn


def precision_rows(run: LoadedRun, dev: str, repeats: int) -> list[dict]:
    """float32, float64 and bfloat16 autocast on the same model and test set."""
    device = torch.device(dev)
    double = model_in(run, torch.float64)
    rows = [{"setting": "k=5 float32", **accuracy(run), **speed(run, device, repeats)},
            {"setting": "k=5 float64", **accuracy(run, predictor=cast_predictor(double, run)),
             **speed(run, device, repeats, double, dtype=torch.float64)}]
    try:
        bf = accuracy(run, predictor=autocast_predictor(run))
        rows.append({"setting": "k=5 bfloat16 autocast", **bf,
                     **speed(run, device, repeats, autocast=True)})
    except RuntimeError as e:         # a device without bfloat16 kernels
        rows.append({"setting": f"bfloat16: not supported here ({e})"})
    return rows


def subsample(fraction: float, seed: int) -> Callable[[Batch], Batch]:
    """Keep a random ``fraction`` of each example's points (another point density)."""
    g = torch.Generator().manual_seed(seed)

    def fn(b: Batch) -> Batch:
        n = b.points.shape[1]
        keep = max(1, round(fraction * n))
        idx = torch.rand(len(b.points), n, generator=g).argsort(1)[:, :keep].to(b.points.device)
        take = idx.unsqueeze(-1).expand(-1, -1, 3)
        return Batch(b.points.gather(1, take), b.target.gather(1, take), b.mask.gather(1, idx),
                     b.cond, b.dforce)

    return fn


def moved(rotations: Callable[[int], torch.Tensor], centre: torch.Tensor
          ) -> Callable[[Batch], Batch]:
    """Each batch turned by ``rotations(batch size)`` about ``centre``."""
    return lambda b: move_batch(b, rotations(len(b.points)), centre)


def robustness_rows(plain: LoadedRun, turned: LoadedRun, seed: int) -> list[dict]:
    """Errors of both models on the moved and resampled test sets, and ratios to unmoved."""
    centre = torch.tensor(plain.norm.centre)
    tests: dict[str, Callable[[Batch], Batch] | None] = {
        "unmoved": None,
        "rotated 90 deg about the normal": moved(
            lambda n: about_normal(torch.full((n,), math.pi / 2)), centre),
        "tilted 10 deg": moved(lambda n: tilt(10.0, n), centre),
        "tilted 30 deg": moved(lambda n: tilt(30.0, n), centre),
        "75 % of the points": subsample(0.75, seed),
        "50 % of the points": subsample(0.5, seed),
    }
    rows = []
    for model_name, run in (("plain", plain), ("rotation-augmented", turned)):
        base = None
        for test, fn in tests.items():
            acc = accuracy(run, fn)
            base = base or acc
            rows.append({"model": model_name, "test": test, **acc,
                         "force_ratio": acc["force_n"] / base["force_n"],
                         "ld_ratio": acc["ld_mm"] / base["ld_mm"]})
    return rows


def point_rows(msm: LoadedRun, dev: str, repeats: int, seed: int) -> list[dict]:
    """Latency at 26 .. 4096 points; accuracy of the MSM model resampled to as many points."""
    grid = msm.states.points.shape[1]
    device = torch.device(dev)
    rows = []
    for n in POINT_COUNTS:
        row = {"points": n, "full_ms": latency(msm.model, n, device, max(5, repeats // 5)),
               "force_ms": latency(msm.model, n, device, max(5, repeats // 5),
                                   force_only=True)}
        if n <= grid:
            row.update(accuracy(msm, subsample(n / grid, seed) if n < grid else None))
        rows.append(row)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=Path("out/speed_accuracy"))
    ap.add_argument("--quick", action="store_true", help="minutes on 2 CPU cores")
    ap.add_argument("--twin", type=Path, default=None,
                    help="a `pipeline demo` output folder (session_states.h5, splits.json)")
    ap.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--epochs", type=int, default=None,
                    help="train every setting this many epochs (a smoke test)")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    set_quiet(True)
    b = QUICK if a.quick else PAPER
    if a.epochs:
        b = replace(b, twin_epochs=a.epochs, msm_epochs=a.epochs, region_epochs=a.epochs)
    a.out.mkdir(parents=True, exist_ok=True)
    twin = twin_data(a.out, a.twin, a.seed)
    msm = msm_data(a.out, b, a.seed)
    print("k ...", flush=True)
    res = {"budget": b.__dict__, "device": device_name(a.device), "k": k_rows(a.out, twin, b,
                                                                              a.device, a.seed)}
    print("fraction ...", flush=True)
    res["fraction"] = fraction_rows(a.out, twin, b, a.device, a.seed)
    plain = load_run(a.out / "runs" / "twin_k5", a.device)
    turned = trained(a.out, "twin_k5_rot", twin, b.twin_epochs, b, a.device, a.seed,
                     rotate=True)
    print("precision, robustness ...", flush=True)
    res["precision"] = precision_rows(plain, a.device, b.repeats)
    res["robustness"] = robustness_rows(plain, turned, a.seed)
    res["augmented"] = [{"setting": "k=5 rotation-augmented", **accuracy(turned),
                         **speed(turned, torch.device(a.device), b.repeats)}]
    msm_run = trained(a.out, f"msm{b.msm_grid}_k5", msm, b.msm_epochs, b, a.device, a.seed)
    print("points, MSM tolerance ...", flush=True)
    res["points"] = point_rows(msm_run, a.device, b.repeats, a.seed)
    print("extremes ...", flush=True)
    res["extremes"] = extreme_rows(a.out / "runs" / "twin_k5",
                                   a.out / "runs" / f"msm{b.msm_grid}_k5", a.seed)
    print("region of interest ...", flush=True)
    res["region"] = region_rows(a.out / "region", b.region_epochs, device=a.device,
                                seed=a.seed, repeats=b.repeats)
    res["msm_tolerance"] = trade_rows(count=3, reference=not a.quick)
    (a.out / "results.json").write_text(json.dumps(res, indent=1))
    write_report(a.out, res, HAPTIC_MS, VISUAL_MS)
    print((a.out / "report.md").read_text())


def device_name(dev: str) -> str:
    """The device and thread count the figures were measured on."""
    if dev == "cuda":
        return torch.cuda.get_device_name()
    return f"CPU, {torch.get_num_threads()} threads, {os.cpu_count()} cores, torch " \
           f"{torch.__version__}"


if __name__ == "__main__":
    main()

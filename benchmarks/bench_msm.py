"""MSM generation: the full 16,500-example set, and the fast path against the reference.

Prints (1) the wall time of the paper's whole protocol (100 locations x 11 directions x 15
steps) with ``--workers`` processes, written to a states file; (2) per-example time of the
fast static path against the reference explicit integration (the paper's method) on the same
sequences in the same run, medians, their ratio and the largest point difference; (3) the trade
of accuracy against time as the fast path's tolerance and the reference's stopping criterion
move, errors against an equilibrium solved to 1e-10 N; (4) what HDF5 compression would cost.

The fast path is timed as the dataset runs it: one solver per location keeps the Cholesky
factor of the rest stiffness for all 11 directions (``sim.msm.msm_simulate._simulate_location``),
so here one solver per tolerance serves every sequence and the rest factorisation is timed on
its own and added, shared by a location's 11 x 15 examples. The paper's 2.93 s per example is
a figure from other code on another CPU: its ratio is printed apart from the in-run ratios.

    python benchmarks/bench_msm.py                 # everything (~2-3 min on 2 free cores)
    python benchmarks/bench_msm.py --skip-full     # only the per-example comparison and trade
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

from sim.msm.blas_threads import blas_threads
from sim.msm.msm import MSM, MSMParams, simulate_reference
from sim.msm.msm_protocol import Protocol, draw_plan
from sim.msm.msm_static import DEFAULT_TOL, BandedTangent, StaticSolver, simulate_sequence
from sim.msm.simulate_stage import generate

PAPER_S_PER_EXAMPLE = 2.93                          # the paper's machine and code
EXAMPLES_PER_LOCATION = 11 * 15                     # share one rest factorisation
PAPER_CRITERION = 0.02                              # m/s and N
TIGHT_CRITERION = 2e-4
FAST_TOLS = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-8)
REF_CRITERIA = (0.02, 2e-3, 2e-4, 2e-5)


def full_set(workers: int, repeats: int) -> None:
    protocol = Protocol()
    n = protocol.sequences * protocol.steps
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "msm.h5"
        walls, cpus = [], []
        for _ in range(repeats):
            t0 = time.perf_counter()
            sim, arrays = generate(out, protocol, MSMParams(), workers=workers)
            walls.append(time.perf_counter() - t0)
            cpus.append(sim.cpu_s)
            print(f"  run: {walls[-1]:.1f} s wall, load average {os.getloadavg()[0]:.1f}")
        wall, cpu = statistics.median(walls), statistics.median(cpus)
        print(f"full set: {n} examples ({len(arrays['states/step'])} states, "
              f"{out.stat().st_size / 1e6:.0f} MB) in {wall:.1f} s wall (median of {repeats}) "
              f"with {workers} workers (target <= 60 s); solves {cpu:.1f} s CPU = "
              f"{cpu / n * 1e3:.2f} ms CPU per example; {sim.factorizations / n:.2f} "
              f"factorizations and {sim.iterations / n:.2f} iterations per example; max "
              f"residual {sim.max_residual:.2g} N as solved, {sim.stored_residual:.2g} N as "
              "stored (float32)")
        print(f"  cross-machine (the paper's code and CPU, not this run): "
              f"{PAPER_S_PER_EXAMPLE * n / 3600:.1f} CPU-hours reported -> {cpu / 60:.1f} "
              f"CPU-minutes here ({PAPER_S_PER_EXAMPLE * n / cpu:.0f}x)")
        compression(arrays, Path(tmp))


def compression(arrays: dict, tmp: Path) -> None:
    points = arrays["states/points"]
    print("  states/points storage (write time, size):")
    for name, kwargs in (("none", {}), ("lzf", {"compression": "lzf"}),
                         ("gzip-1", {"compression": "gzip", "compression_opts": 1})):
        path = tmp / f"c_{name}.h5"
        t0 = time.perf_counter()
        with h5py.File(path, "w") as f:
            chunks = (1, *points.shape[1:]) if kwargs else None
            f.create_dataset("points", data=points, chunks=chunks, **kwargs)
        t = time.perf_counter() - t0
        t0 = time.perf_counter()
        with h5py.File(path, "r") as f:
            f["points"][()]
        r = time.perf_counter() - t0
        size = path.stat().st_size / 1e6
        print(f"    {name:7s} write {t:5.2f} s  read {r:5.2f} s  {size:6.1f} MB")


def sequences(count: int) -> list[tuple[int, np.ndarray]]:
    """The protocol's first locations, alternately the normal and a random direction."""
    plan = draw_plan(Protocol(), 1024)
    return [(int(plan.nodes[k]), plan.directions[k, 0 if k % 2 == 0 else 1 + (k // 2) % 10])
            for k in range(count)]


def timed(fn, *args, **kwargs) -> tuple[float, object]:
    t0 = time.perf_counter()
    out = fn(*args, **kwargs)
    return time.perf_counter() - t0, out


def rest_factorisation(model: MSM, repeats: int) -> float:
    """Median seconds of one Cholesky factorisation of the rest stiffness (per example:
    divide by the examples of a location, which share it)."""
    tangent = BandedTangent(model)
    with blas_threads(1):                        # as the solves run
        tangent.factor(model.rest)               # warm up
        return statistics.median(timed(tangent.factor, model.rest)[0]
                                 for _ in range(max(repeats, 5)))


def per_example(count: int, repeats: int) -> None:
    model = MSM()
    steps = 15
    seqs = sequences(count)
    exact_solver = StaticSolver(model, 1e-10)
    truth = [simulate_sequence(model, n, d, tol=1e-10, solver=exact_solver)
             for n, d in seqs]                                              # also warms up
    simulate_reference(model, *seqs[0], steps=1)
    solver = StaticSolver(model)                  # as the dataset: the rest factor is reused
    factor = rest_factorisation(model, repeats) / EXAMPLES_PER_LOCATION
    fast_t, ref_t, tight_t = [], [], []
    fast_err, ref_err, tight_err, ref_vs_fast = [], [], [], []
    for (node, d), exact in zip(seqs, truth, strict=True):
        ts = [timed(simulate_sequence, model, node, d, solver=solver) for _ in range(repeats)]
        fast_t.append(statistics.median(t for t, _ in ts) / steps + factor)
        fast = ts[0][1]
        t, (ref, _) = timed(simulate_reference, model, node, d)
        ref_t.append(t / steps)
        t, (tight, _) = timed(simulate_reference, model, node, d, v_tol=TIGHT_CRITERION,
                              f_tol=TIGHT_CRITERION)
        tight_t.append(t / steps)
        fast_err.append(_max_mm(fast, exact))
        ref_err.append(_max_mm(ref, exact))
        tight_err.append(_max_mm(tight, exact))
        ref_vs_fast.append((_max_mm(ref, fast), _max_mm(tight, fast)))
    f, r, rt = (statistics.median(v) for v in (fast_t, ref_t, tight_t))
    print(f"\nper example, median of {count} sequences x 15 steps (fast: median of {repeats} "
          "runs), one process, measured in this run:")
    label = f"fast static path (tol {DEFAULT_TOL:g} N)"
    print(f"  {label:41s}{f * 1e3:8.2f} ms   max error "
          f"{max(fast_err):.1e} mm   (incl. rest factorisation {factor * 1e3:.3f} ms = "
          f"{factor * EXAMPLES_PER_LOCATION * 1e3:.1f} ms / {EXAMPLES_PER_LOCATION})")
    print(f"  reference, paper criterion (0.02)        {r * 1e3:8.2f} ms   max error "
          f"{max(ref_err):.1e} mm   ratio {r / f:5.1f}x   fast vs it: "
          f"{max(a for a, _ in ref_vs_fast):.4f} mm")
    print(f"  reference, tightened ({TIGHT_CRITERION:g})            {rt * 1e3:8.2f} ms   "
          f"max error {max(tight_err):.1e} mm   ratio {rt / f:5.1f}x   fast vs it: "
          f"{max(b for _, b in ref_vs_fast):.5f} mm")
    print("cross-machine, not measured here (the paper's own code on its own CPU):")
    print(f"  paper's reported time                    {PAPER_S_PER_EXAMPLE * 1e3:8.0f} ms"
          f"                        ratio {PAPER_S_PER_EXAMPLE / f:5.0f}x")
    trade(model, seqs, truth, repeats, factor)


def trade(model: MSM, seqs: list, truth: list, repeats: int, factor: float) -> None:
    print("\ntrade: max point error against the 1e-10 N equilibrium, and time per example")
    rows = trade_rows(model, seqs, truth, repeats, factor)
    print("  fast path tol (N)   ms/example   max error (mm)   (rest factorisation shared)")
    for r in (r for r in rows if r["solver"] == "fast"):
        print(f"  {r['tol']:16.0e}   {r['ms']:10.2f}   {r['max_err_mm']:.2e}")
    print("  reference criterion (m/s and N)   ms/example   max error (mm)")
    for r in (r for r in rows if r["solver"] == "reference"):
        print(f"  {r['tol']:30.0e}   {r['ms']:10.2f}   {r['max_err_mm']:.2e}")


def trade_rows(model: MSM | None = None, seqs: list | None = None, truth: list | None = None,
               repeats: int = 1, factor: float | None = None, count: int = 4,
               reference: bool = True) -> list[dict]:
    """Time per example and largest error against the 1e-10 N equilibrium, for each fast-path
    tolerance and (``reference``) each reference criterion; the pieces not given (model,
    ``count`` sequences, their truth, the shared factorisation) are made here."""
    model = model or MSM()
    seqs = seqs or sequences(count)
    if truth is None:
        exact = StaticSolver(model, 1e-10)
        truth = [simulate_sequence(model, n, d, tol=1e-10, solver=exact) for n, d in seqs]
    if factor is None:
        factor = rest_factorisation(model, 5) / EXAMPLES_PER_LOCATION
    rows = []
    for tol in FAST_TOLS:
        solver = StaticSolver(model, tol)
        runs = [[timed(simulate_sequence, model, node, d, tol=tol, solver=solver)
                 for _ in range(repeats)] for node, d in seqs]
        rows.append(_trade_row("fast", tol, [statistics.median(t for t, _ in ts) / 15 + factor
                                             for ts in runs],
                               [ts[0][1] for ts in runs], truth))
    for crit in REF_CRITERIA if reference else ():
        runs = [timed(simulate_reference, model, node, d, v_tol=crit, f_tol=crit)
                for node, d in seqs]
        rows.append(_trade_row("reference", crit, [t / 15 for t, _ in runs],
                               [ref for _, (ref, _) in runs], truth))
    return rows


def _trade_row(solver: str, tol: float, seconds: list[float], got: list, truth: list) -> dict:
    return {"solver": solver, "tol": tol, "ms": statistics.median(seconds) * 1e3,
            "max_err_mm": max(_max_mm(g, t) for g, t in zip(got, truth, strict=True))}


def _max_mm(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b, axis=-1).max() * 1e3)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--sequences", type=int, default=6,
                        help="sequences for the per-example comparison and the trade")
    parser.add_argument("--repeats", type=int, default=3, help="fast-path repeats (median)")
    parser.add_argument("--full-repeats", type=int, default=1, help="runs of the full set")
    parser.add_argument("--skip-full", action="store_true")
    args = parser.parse_args()
    print(f"load average at start {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    if not args.skip_full:
        full_set(args.workers, args.full_repeats)
    per_example(args.sequences, args.repeats)


if __name__ == "__main__":
    main()

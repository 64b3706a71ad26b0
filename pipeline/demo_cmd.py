"""``pipeline demo``: every stage on a synthetic session, as a user would type them.

Each step is skipped when its inputs, arguments and the code are unchanged since it last ran
(content hashes, :mod:`pipeline.stage_cache`), and says so; ``--force`` runs everything.
Independent steps (every fold's fit, MSM, pre-training and fine-tunings; the scarcity study)
go side by side in ``--jobs`` worker processes that keep torch and the code loaded from one
step to the next, the cores shared out between them (:mod:`pipeline.demo_pool`; small graphs
keep one core busier than two threads do). The summary scores everything against its targets
(:mod:`pipeline.demo_targets`), and ``demo_times.json`` says how long each stage and step took,
beside the host's figure (:mod:`pipeline.demo_times`).
"""

from __future__ import annotations

import os
import shlex
import shutil
import time
from pathlib import Path

import click

from core.errors import BadInput
from pipeline.demo_plan import (
    NETWORKS,
    OUT,
    PAPER,
    QUICK,
    RECIPE,
    RECIPE_NETWORK,
    SMOKE,
    Lab,
    Pretraining,
    Step,
    demo_steps,
)
from pipeline.demo_pool import WORKERS, Pool, StepResult, ready
from pipeline.demo_times import TIMES, HostFigure, Times, measure_host
from pipeline.options import OneOf, ranged, seed_option
from pipeline.stage_cache import is_fresh, write_doc, write_stamp
from pipeline.synth_cmd import INCLUSION, LAYER, MARKER_PITCH_MM, MARKERS, MOCAP_RATE, SIZE
from sim.twin.synth_params import SynthParams
from train.training.train_params import DEVICES, TrainParams


@click.command()
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=OUT,
              show_default=True, help="Folder for everything the demo writes.")
@click.option("--quick", is_flag=True,
              help="Small MSM sets, short training: minutes on 2 CPU cores (target: 85 x the "
                   "host's figure; demo_times.json says where the time went).")
@click.option("--smoke", is_flag=True,
              help="Only check the wiring: 2 folds, 2 epochs, a tiny MSM set (seconds).")
@click.option("--force", is_flag=True, help="Run every step, even unchanged ones.")
@click.option("--strict", is_flag=True, help="Exit with status 1 when a target is missed.")
@click.option("--device", type=OneOf(DEVICES), default=TrainParams.device,
              show_default=True, help="Where the cGNN trains.")
@click.option("--jobs", type=ranged(WORKERS), default=None,
              help="Worker processes for the independent steps, the cores shared out between "
                   "them [default: the CPU cores; 1 on a GPU: every step in this process].")
@click.option("--host-speed/--no-host-speed", default=None,
              help="First measure the host's figure (core/host_speed.py, about 4 runs of a "
                   "fixed mix of work; not counted in the demo's time) and state the demo's "
                   "time as a multiple of it [default: measured, except with --smoke].")
@click.option("--network", type=OneOf(NETWORKS), default=None,
              help="Train this network with the rest of the recipe [default: the recipe's]: "
                   "the tip's offsets in the heads or in the first layer, or the paper's "
                   "(docs/results.md compares them; docs/model.md, Latency).")
@click.option("--pretraining", type=OneOf(Pretraining), default=Pretraining.SHIPPED.value,
              show_default=True,
              help="shipped: none here, every fold starts from the generic model shipped with "
                   "the package (train/generic_model.pt); generic: that model made here, one "
                   "model for every lab pre-trained once on MSM data drawn from the prior (the "
                   "same whatever the lab or --seed; with --quick the shipped one's recipe); "
                   "per-fold: per fold the MSM fitted on its training presses, simulated at "
                   "the lab's markers and pre-trained on (five times the work); solid: the "
                   "shipped model's runs, and beside them per fold the solid model of the "
                   "phantom with its interior (fit-solid) pressed at the lab's markers, the "
                   "shipped model pre-trained further on it and fine-tuned from there.")
@click.option("--markers", type=MARKERS, default=Lab.markers, show_default=True,
              help="The twin lab's phantom markers: a grid RxC, or scattered:N (synth).")
@click.option("--marker-pitch", type=MARKER_PITCH_MM,
              default=Lab.marker_pitch_mm, show_default=True, help="A grid's pitch (mm).")
@click.option("--size", type=SIZE, default=Lab.size_mm, show_default=True,
              help="The twin lab's phantom footprint LxW (mm).")
@click.option("--mocap-rate", type=MOCAP_RATE,
              default=Lab.mocap_rate_hz, show_default=True, help="The twin lab's mocap rate.")
@click.option("--inclusion", "inclusions", type=INCLUSION, multiple=True,
              help="A lump in the twin lab's phantom, X,Y,DEPTH,RADIUS,RATIO (synth; repeat "
                   "for more); every run on the lab learns the force from unturned presses "
                   "(train --no-rotate-force), and eval reports the errors over the first "
                   "and away from it.")
@click.option("--layer", type=LAYER, default=Lab.layer,
              help="A top layer in the twin lab's phantom, THICKNESS,RATIO (synth).")
@click.option("--shape", default=Lab.shape,
              help="A curved twin lab: dome:HEIGHT (mm) or a mould's STL/OBJ/PLY (synth); with "
                   "--pretraining shipped or solid its folds start from the generic model for "
                   "curved labs (train/generic_curved_model.pt), where a flat lab's start from "
                   "the shipped generic model.")
@seed_option(SynthParams.seed)
@click.pass_context
def demo(ctx: click.Context, out: Path, quick: bool, smoke: bool, force: bool, strict: bool,
         device: str, jobs: int | None, host_speed: bool | None, network: str | None,
         pretraining: Pretraining, markers: str, marker_pitch: float, size: str, mocap_rate: float,
         inclusions: tuple[str, ...], layer: str | None, shape: str | None, seed: int) -> None:
    """Run every stage on a synthetic session, from lab files to a trained, evaluated cGNN.

    Reads nothing. Writes, under --out: session/ (the phantom twin's lab files and truth.h5;
    --markers, --size and --mocap-rate make it another lab's phantom), session.mcap,
    session_synced.h5, session_states.h5 and splits.json (ingest, sync, extract, split);
    the pre-training: none with the shipped generic model (the default), with --pretraining
    generic msm/prior.h5 and prior_splits.json (MSM data drawn from the prior) and
    runs/generic (the generic model), or with --pretraining per-fold, per fold msm/foldK/
    (params.json: fit-msm on that fold's training presses only; msm.h5 and splits.json: that
    MSM, sized to the footprint, sampled at the markers' layout) and runs/msm_foldK, or with
    --pretraining solid, per fold solid/foldK/ (solid.json: fit-solid on that fold's training
    presses with the session's interior; states.h5: that solid pressed at the markers) and
    runs/solid_foldK (the shipped model pre-trained on it), fine-tuned into runs/exp_solid_*;
    runs/exp_tl_* and runs/exp_notl_* (fine-tuning per fold with transfer learning from the
    pre-trained model and the same from scratch);
    metrics.json/.md (eval, beside the no-learning references), scarcity/ (the data-scarcity
    study), a rerun recording beside each, demo_times.json (each stage's and step's wall
    time, beside the host's figure) and a summary against the targets. Without
    --quick it follows the paper's settings (hours on a CPU; uses a GPU when there is one).
    """
    from pipeline.demo_targets import summary

    settings = SMOKE if smoke else QUICK if quick else PAPER
    if pretraining.from_shipped and network not in (None, RECIPE_NETWORK):
        raise BadInput("--network", f"{network}: the shipped generic model is the recipe's "
                       "network; make one of this network with --pretraining generic (or "
                       "per-fold)")
    jobs = jobs or (1 if _on_gpu(device) else _cores())
    threads = max(1, _cores() // jobs)
    host = _host_figure(not smoke if host_speed is None else host_speed)
    started = time.perf_counter()
    lab = Lab(markers, marker_pitch, size, mocap_rate, inclusions, layer, shape)
    steps = demo_steps(out, seed, settings, device,
                       NETWORKS[network] if network else RECIPE, lab, pretraining)
    times = Times()
    with Pool(jobs, threads) as pool:
        for batch in _batches(steps):
            _run_batch(ctx, batch, force, pool, times)
    seconds = time.perf_counter() - started
    tic = time.perf_counter()
    missed = summary(out, seconds, quick=quick, host_s=host.seconds)
    write_doc(out / TIMES, times.document(seconds, time.perf_counter() - tic, host, jobs,
                                          threads))
    click.echo(f"each stage's and step's time: {out / TIMES}")
    if missed and strict:
        ctx.exit(1)


def _host_figure(measure: bool) -> HostFigure:
    """The host's figure, measured and said, or absent (``--no-host-speed``, ``--smoke``)."""
    if not measure:
        return HostFigure(None, "absent: not measured (--no-host-speed, or --smoke)")
    host = measure_host()
    click.echo(f"{host.note} (measured in {host.cost_s:.1f} s, not counted in the demo's "
               "time)", err=True)
    return host


def _on_gpu(device: str) -> bool:
    """Whether the runs train on a GPU (``auto`` picks one when torch has it)."""
    if device == "auto":
        import torch

        return torch.cuda.is_available()
    return device == "cuda"


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def _batches(steps: list[Step]) -> list[list[Step]]:
    """Consecutive parallel steps of one batch together; every other step alone."""
    out: list[list[Step]] = []
    for step in steps:
        if step.parallel and out and out[-1][-1].parallel and out[-1][-1].batch == step.batch:
            out[-1].append(step)
        else:
            out.append([step])
    return out


def _run_batch(ctx: click.Context, batch: list[Step], force: bool, pool: Pool,
               times: Times) -> None:
    """Run the stale steps of a batch: parallel ones in the worker processes (with more
    than one job), every other in this process; each one's time into ``times``."""
    stale: list[Step] = []
    for step in batch:
        line = f"\n$ pipeline {shlex.join(step.args)}"
        upstream_stale = not ready(step, stale)    # it reads what a stale step rewrites
        if not force and not upstream_stale and is_fresh(step.args, step.inputs, step.outputs):
            click.echo(f"{line}\n  (unchanged since its last run: skipped)", err=True)
            times.step(step, 0.0, "demo", skipped=True)
        else:
            stale.append(step)
    tic = time.perf_counter()
    if stale and pool.size > 1 and all(s.parallel for s in stale):
        _run_in_workers(stale, pool, times)
    else:
        for step in stale:
            _run_here(ctx, step, times)
    if stale:
        times.batch(stale, time.perf_counter() - tic, min(pool.size, len(stale))
                    if stale[0].parallel else 1)


def _run_here(ctx: click.Context, step: Step, times: Times) -> None:
    """``pipeline ARGS`` in this process."""
    click.echo(f"\n$ pipeline {shlex.join(step.args)}", err=True)
    tic = time.perf_counter()
    _clean(step)
    root = ctx.find_root().command
    with root.make_context("pipeline", list(step.args), parent=ctx.find_root()) as sub:
        root.invoke(sub)
    write_stamp(step.args, step.inputs, step.outputs)
    seconds = time.perf_counter() - tic
    times.step(step, seconds, "demo")
    click.echo(f"  ({seconds:.1f} s)", err=True)


def _clean(step: Step) -> None:
    for path in step.clean:
        shutil.rmtree(path, ignore_errors=True)


def _run_in_workers(steps: list[Step], pool: Pool, times: Times) -> None:
    """The steps in the pool's workers, each as soon as its inputs are written; a failing
    step stops the demo with its own message and exit status."""
    tic = time.perf_counter()
    finished = 0
    click.echo(f"\n$ ({len(steps)} runs, {pool.size} worker processes of {pool.threads} "
               "thread(s), each run as its inputs are ready)", err=True)

    def started(step: Step, worker: int) -> None:
        click.echo(f"  $ pipeline {shlex.join(step.args)}   [worker {worker}]", err=True)
        _clean(step)

    def done(step: Step, result: StepResult) -> None:
        nonlocal finished
        finished += 1
        write_stamp(step.args, step.inputs, step.outputs)
        times.step(step, result.seconds, f"worker {result.worker}")
        click.echo(f"  [{finished}/{len(steps)}] {step.outputs[0]}: {result.seconds:.1f} s",
                   err=True)

    pool.run(steps, started, done)
    click.echo(f"  ({time.perf_counter() - tic:.1f} s)", err=True)

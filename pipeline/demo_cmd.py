"""``pipeline demo``: every stage on a synthetic session, as a user would type them.

Each step is skipped when its inputs, arguments and the code are unchanged since it last ran
(content hashes, :mod:`pipeline.stage_cache`), and says so; ``--force`` runs everything.
Independent training runs go side by side in ``--jobs`` processes of one thread each (small
graphs keep one core busier than two threads do). The summary scores everything against its
targets (:mod:`pipeline.demo_targets`).
"""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import click

from pipeline.demo_plan import NETWORKS, PAPER, QUICK, RECIPE, SMOKE, Lab, Step, demo_steps
from pipeline.options import seed_option
from pipeline.stage_cache import is_fresh, write_stamp
from pipeline.synth_cmd import MARKER_PITCH_MM, MARKERS, MOCAP_RATE, SIZE


@click.command()
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("out/demo"),
              show_default=True, help="Folder for everything the demo writes.")
@click.option("--quick", is_flag=True,
              help="Small MSM sets, short training: 6-9 minutes on 2 CPU cores (target 5).")
@click.option("--smoke", is_flag=True,
              help="Only check the wiring: 2 folds, 2 epochs, a tiny MSM set (seconds).")
@click.option("--force", is_flag=True, help="Run every step, even unchanged ones.")
@click.option("--strict", is_flag=True, help="Exit with status 1 when a target is missed.")
@click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="auto",
              show_default=True, help="Where the cGNN trains.")
@click.option("--jobs", type=click.IntRange(min=1), default=None,
              help="Independent training runs side by side [default: the CPU cores; 1 on a "
                   "GPU].")
@click.option("--network", type=click.Choice(list(NETWORKS)), default=None,
              help="Train this network with the rest of the recipe [default: the recipe's]: "
                   "the tip's offsets in the heads or in the first layer, or the paper's "
                   "(docs/results.md compares them; docs/model.md, Latency).")
@click.option("--markers", type=MARKERS, default=Lab.markers, show_default=True,
              help="The twin lab's phantom markers: a grid RxC, or scattered:N (synth).")
@click.option("--marker-pitch", type=MARKER_PITCH_MM,
              default=Lab.marker_pitch_mm, show_default=True, help="A grid's pitch (mm).")
@click.option("--size", type=SIZE, default=Lab.size_mm, show_default=True,
              help="The twin lab's phantom footprint LxW (mm).")
@click.option("--mocap-rate", type=MOCAP_RATE,
              default=Lab.mocap_rate_hz, show_default=True, help="The twin lab's mocap rate.")
@seed_option
@click.pass_context
def demo(ctx: click.Context, out: Path, quick: bool, smoke: bool, force: bool, strict: bool,
         device: str, jobs: int | None, network: str | None, markers: str,
         marker_pitch: float, size: str, mocap_rate: float, seed: int) -> None:
    """Run every stage on a synthetic session, from lab files to a trained, evaluated cGNN.

    Reads nothing. Writes, under --out: session/ (the phantom twin's lab files and truth.h5;
    --markers, --size and --mocap-rate make it another lab's phantom), session.mcap,
    session_synced.h5, session_states.h5 and splits.json (ingest, sync, extract, split);
    per fold msm/foldK/ (params.json: fit-msm on that fold's training presses only; msm.h5
    and splits.json: that MSM, sized to the footprint, sampled at the markers' layout) and
    runs/msm_foldK (pre-training on it); runs/exp_tl_* and runs/exp_notl_* (fine-tuning per
    fold with transfer learning and the same from scratch);
    metrics.json/.md (eval, beside the no-learning references), scarcity/ (the data-scarcity
    study), a rerun recording beside each, and a summary against the targets. Without
    --quick it follows the paper's settings (hours on a CPU; uses a GPU when there is one).
    """
    from pipeline.demo_targets import summary

    settings = SMOKE if smoke else QUICK if quick else PAPER
    jobs = jobs or (1 if _on_gpu(device) else _cores())
    started = time.perf_counter()
    lab = Lab(markers, marker_pitch, size, mocap_rate)
    steps = demo_steps(out, seed, settings, device,
                       NETWORKS[network] if network else RECIPE, lab)
    for batch in _batches(steps):
        _run_batch(ctx, batch, force, jobs)
    missed = summary(out, time.perf_counter() - started, quick=quick)
    if missed and strict:
        ctx.exit(1)


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


def _run_batch(ctx: click.Context, batch: list[Step], force: bool, jobs: int) -> None:
    """Run the stale steps of a batch: in this process, or ``jobs`` subprocesses at a time."""
    stale: list[Step] = []
    for step in batch:
        line = f"\n$ pipeline {shlex.join(step.args)}"
        upstream_stale = not _ready(step, stale)    # it reads what a stale step rewrites
        if not force and not upstream_stale and is_fresh(step.args, step.inputs, step.outputs):
            click.echo(f"{line}\n  (unchanged since its last run: skipped)", err=True)
        else:
            stale.append(step)
    if len(stale) > 1 and jobs > 1:
        _run_side_by_side(stale, jobs)
        return
    for step in stale:
        click.echo(f"\n$ pipeline {shlex.join(step.args)}", err=True)
        tic = time.perf_counter()
        _clean(step)
        root = ctx.find_root().command
        with root.make_context("pipeline", list(step.args), parent=ctx.find_root()) as sub:
            root.invoke(sub)
        write_stamp(step.args, step.inputs, step.outputs)
        click.echo(f"  ({time.perf_counter() - tic:.1f} s)", err=True)


def _clean(step: Step) -> None:
    for path in step.clean:
        shutil.rmtree(path, ignore_errors=True)


def _ready(step: Step, pending: list[Step]) -> bool:
    """Whether no pending step (waiting or running) writes one of ``step``'s inputs."""
    return not any(set(step.inputs) & set(other.outputs) for other in pending)


def _run_side_by_side(steps: list[Step], jobs: int) -> None:
    """``pipeline -q ARGS`` of each step in subprocesses, ``jobs`` at a time, one thread each,
    the first step in order whose inputs are written starting as soon as a slot is free; a
    failing step stops the demo with its own message and exit status."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    waiting, running = list(steps), []
    tic = time.perf_counter()
    click.echo(f"\n$ ({len(steps)} runs, {jobs} at a time, each as its inputs are ready)",
               err=True)
    while waiting or running:
        pending = waiting + [r[0] for r in running]
        ready = [s for s in waiting if _ready(s, [p for p in pending if p is not s])]
        while ready and len(running) < jobs:
            step = ready.pop(0)
            waiting.remove(step)
            click.echo(f"  $ pipeline {shlex.join(step.args)}", err=True)
            _clean(step)
            log = tempfile.TemporaryFile(mode="w+")
            proc = subprocess.Popen([sys.executable, "-m", "pipeline", "-q", *step.args],
                                    env=env, stdout=subprocess.DEVNULL, stderr=log, text=True)
            running.append((step, proc, log))
        time.sleep(0.05)
        for item in [r for r in running if r[1].poll() is not None]:
            running.remove(item)
            step, proc, log = item
            if proc.returncode != 0:
                for _, other, _ in running:
                    other.kill()
                log.seek(0)
                click.echo(log.read().rstrip(), err=True)
                raise SystemExit(proc.returncode)
            log.close()
            write_stamp(step.args, step.inputs, step.outputs)
    click.echo(f"  ({time.perf_counter() - tic:.1f} s)", err=True)

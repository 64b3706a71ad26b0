"""``pipeline demo``: every stage on a synthetic session, as a user would type them.

Each step is skipped when its inputs, arguments and the code are unchanged since it last ran
(content hashes, :mod:`pipeline.stage_cache`), and says so; ``--force`` runs everything.
"""

from __future__ import annotations

import json
import shlex
import shutil
import time
from pathlib import Path

import click

from pipeline.demo_plan import PAPER, QUICK, SMOKE, Step, demo_steps
from pipeline.options import seed_option
from pipeline.stage_cache import is_fresh, write_stamp

TL_CUT = 0.20          # transfer learning must cut the mean distance error by this much


@click.command()
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("out/demo"),
              show_default=True, help="Folder for everything the demo writes.")
@click.option("--quick", is_flag=True,
              help="Small MSM set, short training: under 10 minutes on 2 CPU cores.")
@click.option("--smoke", is_flag=True,
              help="Only check the wiring: 2 folds, 2 epochs, a tiny MSM set (seconds).")
@click.option("--force", is_flag=True, help="Run every step, even unchanged ones.")
@click.option("--strict", is_flag=True, help="Exit with status 1 when a target is missed.")
@click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="auto",
              show_default=True, help="Where the cGNN trains.")
@seed_option
@click.pass_context
def demo(ctx: click.Context, out: Path, quick: bool, smoke: bool, force: bool, strict: bool,
         device: str, seed: int) -> None:
    """Run every stage on a synthetic session, from lab files to a trained, evaluated cGNN.

    Reads nothing. Writes, under --out: session/ (the phantom twin's lab files and truth.h5),
    session.mcap (ingest), synced.h5 (sync), states.h5 and splits.json (extract, split),
    msm.h5 and msm_splits.json (simulate, split), runs/msm (pre-training on MSM), runs/exp_tl_*,
    runs/exp_notl_* and runs/exp_rot_* (fine-tuning on the twin's states per fold with transfer
    learning, without it, and without it but with rotation augmentation), metrics.json/.md
    (eval), a rerun recording beside each, and a summary against
    the accuracy targets. Without --quick it follows the paper's settings (hours on a CPU;
    uses a GPU when there is one).
    """
    settings = SMOKE if smoke else QUICK if quick else PAPER
    started = time.perf_counter()
    for step in demo_steps(out, seed, settings, device):
        _run(ctx, step, force)
    missed = _summary(out, time.perf_counter() - started)
    if missed and strict:
        ctx.exit(1)


def _run(ctx: click.Context, step: Step, force: bool) -> None:
    """Run one step through the CLI (or say why it is skipped), then stamp it."""
    line = f"\n$ pipeline {shlex.join(step.args)}"
    if not force and is_fresh(step.args, step.inputs, step.outputs):
        click.echo(f"{line}\n  (unchanged since its last run: skipped)", err=True)
        return
    click.echo(line, err=True)
    for path in step.clean:
        shutil.rmtree(path, ignore_errors=True)
    tic = time.perf_counter()
    root = ctx.find_root().command
    sub = root.make_context("pipeline", list(step.args), parent=ctx.find_root())
    with sub:
        root.invoke(sub)
    write_stamp(step.args, step.inputs, step.outputs)
    click.echo(f"  ({time.perf_counter() - tic:.1f} s)", err=True)


def _summary(out: Path, seconds: float) -> list[str]:
    """Print the accuracy against the targets and the recordings; the targets missed."""
    from calib.sync_accuracy import TARGETS, sync_errors

    missed = []
    errors = sync_errors(out / "synced.h5", out / "session" / "truth.h5")
    click.echo("\nsync against the twin's truth (error / target):")
    for key, target in TARGETS.items():
        ok = errors[key] <= target
        missed += [] if ok else [key]
        click.echo(f"  {key:18} {errors[key]:9.4f} / {target:<6} {'ok' if ok else 'MISSED'}")
    click.echo("\n" + (out / "metrics.md").read_text())
    overall = {r["label"]: r["metrics"]["all"]
               for r in json.loads((out / "metrics.json").read_text())["overall"]}
    tl = next((v for k, v in overall.items() if k.endswith("(TL)")), None)
    base = overall.get("cGNN/Exp")
    if tl and base:
        cut = 1 - tl["ld_mean_mm"] / base["ld_mean_mm"]
        ok = cut >= TL_CUT
        missed += [] if ok else ["transfer_learning"]
        click.echo(f"transfer learning cuts the mean distance error by {cut:.0%} (target "
                   f"{TL_CUT:.0%}, paper 23%): {'ok' if ok else 'MISSED'}")
    rot = overall.get("cGNN/rot Exp")
    if rot and base:
        click.echo(f"rotation augmentation cuts it by "
                   f"{1 - rot['ld_mean_mm'] / base['ld_mean_mm']:.0%} (no target)")
    click.echo(f"\ndemo finished in {seconds / 60:.1f} min: outputs in {out}; recordings:\n  "
               + "\n  ".join(str(p) for p in sorted(out.rglob("*.rrd"))))
    return missed

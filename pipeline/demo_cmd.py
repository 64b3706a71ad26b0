"""``pipeline demo``: every stage on a small synthetic session, as a user would type them."""

from __future__ import annotations

import shlex
import time
from pathlib import Path

import click

from pipeline.options import seed_option


def demo_steps(out: Path, seed: int) -> list[list[str]]:
    """The command lines the demo runs, in order (also printed, so they can be copied)."""
    s = str(seed)
    return [
        ["synth", str(out / "session"), "--seed", s, "--locations", "5", "--repeats", "4"],
        ["ingest", str(out / "session"), "--out", str(out / "session.mcap")],
        ["sync", str(out / "session.mcap"), "--out", str(out / "synced.h5")],
        ["simulate", "--out", str(out / "msm.h5"), "--locations", "10", "--directions", "3",
         "--seed", s],
        ["inspect", str(out / "session.mcap")],
    ]


@click.command()
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("out/demo"),
              show_default=True, help="Folder for everything the demo writes.")
@seed_option
@click.pass_context
def demo(ctx: click.Context, out: Path, seed: int) -> None:
    """Run every stage on a synthetic session (a default twin session, a small MSM set; ~20 s).

    Reads nothing. Writes, under --out: session/ (the phantom twin's lab files and truth.h5),
    session.mcap (ingest), synced.h5 (sync), msm.h5 (mass-spring states), and a rerun
    recording beside each (open one with `rerun FILE.rrd`).
    """
    root = ctx.find_root().command
    for args in demo_steps(out, seed):
        click.echo(f"\n$ pipeline {shlex.join(args)}", err=True)
        started = time.perf_counter()
        sub = root.make_context("pipeline", list(args), parent=ctx.find_root())
        with sub:
            root.invoke(sub)
        click.echo(f"  ({time.perf_counter() - started:.1f} s)", err=True)
    _report_accuracy(out)
    click.echo(f"\ndemo finished: outputs in {out}; recordings: "
               + ", ".join(str(p) for p in sorted(out.rglob("*.rrd"))))


def _report_accuracy(out: Path) -> None:
    """Print how close sync came to the twin's truth, against the accuracy targets."""
    from pipeline.sync_accuracy import TARGETS, sync_errors

    errors = sync_errors(out / "synced.h5", out / "session" / "truth.h5")
    click.echo("\nsync against the twin's truth (error / target):")
    for key, target in TARGETS.items():
        mark = "ok" if errors[key] <= target else "OVER"
        click.echo(f"  {key:18} {errors[key]:9.4f} / {target:<6} {mark}")

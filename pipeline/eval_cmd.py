"""``pipeline eval``: the click layer over :func:`train.evaluation.eval_stage.run_eval`."""

from __future__ import annotations

from pathlib import Path

import click

from pipeline.options import OneOf, ranged, resolve_rrd, rrd_option
from train.evaluation.eval_params import DEVICES, EvalParams
from train.evaluation.lump import LUMP_REACH_M

D = EvalParams              # the option defaults are its fields', the bounds its BOUNDS


@click.command(name="eval")
@click.argument("runs", nargs=-1, required=True,
                type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option("--out", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Metrics JSON to write; the Markdown table goes beside it (.md).")
@click.option("--scarcity", is_flag=True,
              help="Also retrain each run's fold on 1..n training groups, with and without "
                   "its transfer learning, and write the curve (.scarcity.json/.csv/.png; "
                   "each retrained model with its 90 % intervals' coverage).")
@click.option("--scarcity-epochs", type=ranged(D.BOUNDS["scarcity_epochs"]),
              default=D.scarcity_epochs,
              help="Epochs of each scarcity run [default: the run's own].")
@click.option("--scarcity-groups", type=ranged(D.BOUNDS["scarcity_groups"]),
              default=D.scarcity_groups,
              help="Retrain on 1..N training groups only [default: all of the fold's].")
@click.option("--device", type=OneOf(DEVICES), default=D.device, show_default=True)
@click.option("--strict", is_flag=True,
              help="Exit with status 1 when a variant's mean L_d or force error does not beat "
                   "the best no-learning reference on the same test examples.")
@click.option("--lump", default=D.lump, metavar="X,Y,R",
              help="A lump on the footprint (mm, phantom frame: centre and radius): also "
                   "report L_d, the force error and the intervals' coverage over it (test "
                   f"presses within R + {LUMP_REACH_M * 1e3:g} mm) and away from it, each "
                   "beside the references.")
@click.option("--truth", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              default=D.truth,
              help="A twin's truth.h5: its first inclusion is the lump (instead of --lump).")
@rrd_option
@click.pass_context
def eval_(ctx: click.Context, runs: tuple[Path, ...], out: Path, scarcity: bool,
          scarcity_epochs: int | None, scarcity_groups: int | None, device: str, strict: bool,
          lump: str | None, truth: Path | None, rrd: Path | None, no_rrd: bool) -> None:
    """Evaluate trained runs on their folds' test examples (the paper's Table 2).

    Reads RUNS (folders from `pipeline train`: best.pt, which names its data and manifest).
    Writes --out (JSON, phantom.metrics 1.0 with its provenance: per run and per variant
    pooled over folds, single- and multi-step apart: force MSE, force absolute error mean +-
    sd, mean and max distance error L_d mean +- sd over examples), the same as a Markdown
    table (--out with .md), and a rerun recording of predicted beside true surfaces coloured
    by error and of predicted beside true force (--rrd, default beside --out). Every run is
    scored beside three predictors that learn nothing (nothing moves; the nearest training
    press's displacement; force linear in the tip's motion), on the same test examples, with
    its gain over the best of them. Where a run's best.pt keeps intervals (calibrated on its
    fold's validation presses), also their coverage on the test presses at 80, 90 and 95 %
    (points inside their radius, the force inside its interval, mean widths), each beside
    the range a calibrated table's share falls in by chance (the fold's calibration presses
    re-drawn among its held-out presses, per run and pooled), and the recording colours
    the points by error over their 90 % radius; a run without them is said in one line.
    The recording also shows each test place on the footprint by its mean L_d; with --lump
    or --truth, the lump, and metrics.json (phantom.metrics 1.6) and the table carry the rows
    over the lump and away from it.
    """
    from train.evaluation.eval_stage import run_eval
    from train.evaluation.metrics_table import not_beating

    rrd_path = resolve_rrd(out, rrd, no_rrd)
    result, table = run_eval(runs, out, EvalParams(device, scarcity, scarcity_epochs,
                                                   scarcity_groups, lump, truth), rrd_path)
    click.echo(table + f"\nwrote {out}, {out.with_suffix('.md')}"
               + (f", {rrd_path}" if rrd_path else ""))
    worse = not_beating(result)
    for line in worse:
        click.echo(f"NOT BEATING THE REFERENCES: {line}", err=True)
    if worse and strict:
        ctx.exit(1)

"""``pipeline eval``: the click layer over :mod:`train.evaluate` and :mod:`train.scarcity`."""

from __future__ import annotations

from pathlib import Path

import click

from pipeline.options import resolve_rrd, rrd_option


@click.command(name="eval")
@click.argument("runs", nargs=-1, required=True,
                type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option("--out", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Metrics JSON to write; the Markdown table goes beside it (.md).")
@click.option("--scarcity", is_flag=True,
              help="Also retrain each run's fold on 1..n training groups, with and without "
                   "its transfer learning, and write the curve (.scarcity.json/.csv/.png).")
@click.option("--scarcity-epochs", type=click.IntRange(min=1), default=None,
              help="Epochs of each scarcity run [default: the run's own].")
@click.option("--scarcity-groups", type=click.IntRange(min=1), default=None,
              help="Retrain on 1..N training groups only [default: all of the fold's].")
@click.option("--device", type=click.Choice(["cpu", "cuda"]), default="cpu", show_default=True)
@click.option("--strict", is_flag=True,
              help="Exit with status 1 when a variant's mean L_d or force error does not beat "
                   "the best no-learning reference on the same test examples.")
@rrd_option
@click.pass_context
def eval_(ctx: click.Context, runs: tuple[Path, ...], out: Path, scarcity: bool,
          scarcity_epochs: int | None, scarcity_groups: int | None, device: str, strict: bool,
          rrd: Path | None, no_rrd: bool) -> None:
    """Evaluate trained runs on their folds' test examples (the paper's Table 2).

    Reads RUNS (folders from `pipeline train`: best.pt, which names its data and manifest).
    Writes --out (JSON: per run and per variant pooled over folds, single- and multi-step
    apart: force MSE, force absolute error mean +- sd, mean and max distance error L_d mean
    +- sd over examples), the same as a Markdown table (--out with .md), and a rerun recording
    of predicted beside true surfaces coloured by error and of predicted beside true force
    (--rrd, default beside --out). Every run is scored beside three predictors that learn
    nothing (nothing moves; the nearest training press's displacement; force linear in the
    tip's motion), on the same test examples, with its gain over the best of them.
    """
    from core.atomic import atomic_output
    from train.eval_view import write_eval_recording
    from train.evaluate import evaluate_runs, not_beating, table2, test_errors, write_json

    rrd_path = resolve_rrd(out, rrd, no_rrd)
    result = evaluate_runs(list(runs), device)
    if scarcity:
        result["scarcity"] = _scarcity(runs, out, scarcity_epochs, scarcity_groups, device)
    write_json(out, result)
    table = table2(result)
    with atomic_output(out.with_suffix(".md")) as tmp:
        tmp.write_text(table)
    if rrd_path:
        write_eval_recording(rrd_path, test_errors(runs[0], device)[2])
    click.echo(table + f"\nwrote {out}, {out.with_suffix('.md')}"
               + (f", {rrd_path}" if rrd_path else ""))
    worse = not_beating(result)
    for line in worse:
        click.echo(f"NOT BEATING THE REFERENCES: {line}", err=True)
    if worse and strict:
        ctx.exit(1)


def _scarcity(runs: tuple[Path, ...], out: Path, epochs: int | None, most: int | None,
              device: str) -> list:
    from train.scarcity import plot, scarcity_rows, write_csv

    rows = []
    for run in runs:
        rows += scarcity_rows(run, out.parent / f"{out.stem}.scarcity_runs", epochs, device,
                              most)
    write_csv(out.with_suffix(".scarcity.csv"), rows)
    plot(out.with_suffix(".scarcity.png"), rows)
    return rows

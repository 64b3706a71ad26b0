"""``pipeline split``: the click layer over :func:`split.split_stage.run_split`."""

from __future__ import annotations

from pathlib import Path

import click

from pipeline.options import OneOf, Parsed, ranged, resolve_rrd, rrd_option, seed_option
from split.split import parse_ratio
from split.split_params import DEFAULTS, GROUPINGS, SplitParams

D = SplitParams             # the option defaults are its fields', or the data's (DEFAULTS)
LAB, MSM = DEFAULTS["lab"], DEFAULTS["msm"]


@click.command()
@click.argument("states", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--out", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Fold manifest to write (JSON, schema phantom.folds 2.0).")
@click.option("--folds", type=ranged(D.BOUNDS["folds"]), default=D.folds, show_default=True,
              help="Number of folds.")
@click.option("--ratio", type=Parsed("TRAIN:VAL:TEST", parse_ratio), default=D.ratio,
              help=f"TRAIN:VAL:TEST group counts ratio [default: {':'.join(map(str, LAB[1]))} "
                   f"lab, {':'.join(map(str, MSM[1]))} MSM].")
@click.option("--group", "group_by", type=OneOf(GROUPINGS),
              default=D.group_by,
              help="Keep whole presses (sequence) or whole places (location) in one role "
                   f"[default: {LAB[0]} for lab states, {MSM[0]} for MSM].")
@seed_option(D.seed)
@rrd_option
def split(states: Path, out: Path, folds: int, ratio: tuple[int, int, int] | None,
          group_by: str | None, seed: int, rrd: Path | None, no_rrd: bool) -> None:
    """Split a states file into k folds of train/val/test examples, grouped.

    Reads STATES (phantom.states 2.x, from `pipeline extract` or `pipeline simulate`). Writes
    --out: per fold the group ids and the single-/multi-step example ids of each role, nested
    training subsets of 1..n groups (data-scarcity study), the states file's name and sha256
    (trainers refuse a manifest whose data changed), and a rerun recording of the fold roles on
    the phantom footprint (--rrd, default beside --out).
    """
    from split.split_stage import run_split

    rrd_path = resolve_rrd(out, rrd, no_rrd)
    params = SplitParams(group_by=group_by, ratio=ratio, folds=folds, seed=seed)
    doc = run_split(states, out, params, rrd_path)
    f0 = doc["folds"][0]
    click.echo(f"{out}: {len(doc['folds'])} folds over {doc['groups']} {doc['group_by']} groups "
               f"({':'.join(map(str, doc['ratio']))}: fold 0 trains on "
               f"{len(f0['train']['groups'])}, validates on {len(f0['val']['groups'])}, tests "
               f"on {len(f0['test']['groups'])}); {doc['note']}"
               + (f"; recording {rrd_path}" if rrd_path else ""))

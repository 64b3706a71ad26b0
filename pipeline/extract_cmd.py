"""``pipeline extract``: the click layer over :func:`extract.extract_stage.run_extract`."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from core.text import count
from extract.extract_params import ExtractParams
from pipeline.options import SIZE_MM, ranged, resolve_rrd, rrd_option, seed_option

D = ExtractParams           # the option defaults are its fields', the bounds its BOUNDS

if TYPE_CHECKING:
    from extract.extract import Extracted


@click.command()
@click.argument("synced", nargs=-1, required=True,
                type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--out", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="States file to write (schema phantom.states 2.3).")
@click.option("--step", "step_n", type=ranged(D.BOUNDS["step_n"]), default=D.step_n,
              show_default=True,
              help="Force level spacing, N: at least 3 x the force noise sync measured (and "
                   "1/320 N, a Nano17's resolution), at most the largest peak force.")
@click.option("--max-speed", type=ranged(D.BOUNDS["max_speed"]),
              default=D.max_speed,
              help="Drop states whose surface moved faster than this (m/s): not quasi-static.")
@click.option("--half-window-ms", type=ranged(D.BOUNDS["half_window_s"], 1e3, "ms"),
              default=D.half_window_s * 1e3, show_default=True,
              help="Frames within this of a level's instant are fitted.")
@click.option("--phantom-size", "size_m", type=SIZE_MM, default=D.size_m,
              help="Phantom footprint LxW in mm, overriding session.toml's [phantom] size_mm "
                   "(which sync keeps in the synced file; default 100x100).")
@click.option("--shared-locations", is_flag=True, default=D.shared_locations,
              help="The synced files' location ids name the same places in every session.")
@seed_option(D.seed)
@rrd_option
def extract(synced: tuple[Path, ...], out: Path, step_n: float, max_speed: float | None,
            half_window_ms: float, size_m: tuple[float, float] | None,
            shared_locations: bool, seed: int,
            rrd: Path | None, no_rrd: bool) -> None:
    """Extract static states every --step N from synced presses, with training examples.

    Reads SYNCED files (from `pipeline sync`). In each press's loading phase, takes the
    points (the N phantom markers, then the tip) and the force at the instant the force
    first reaches each level (k = 0: the surface just before contact), from a line fitted
    over the frames around it; moves them into the phantom frame (rest surface z = 0, +z
    out, the footprint and in-plane axis from session.toml's [phantom] layout, which the
    synced file carries); builds single-step (t -> t+1) and multi-step examples (15 random
    pairs at least two levels apart per press, seeded). Writes --out (HDF5 phantom.states
    2.1, with the point names and the footprint) and a rerun recording of the levels on each
    force curve and the states in 3D (--rrd, default beside --out). Presses whose force sync
    flagged as saturated (gauge on the amplifier's rail) or beyond the sensor's rated load
    are left out whole. Excluded presses and dropped states
    are counted in the file and printed.
    """
    from extract.extract_stage import run_extract

    params = ExtractParams(step_n=step_n, half_window_s=half_window_ms * 1e-3,
                           max_speed=max_speed, seed=seed, size_m=size_m,
                           shared_locations=shared_locations)
    rrd_path = resolve_rrd(out, rrd, no_rrd)
    ex = run_extract(synced, out, params, rrd_path)
    a = ex.arrays
    presses = len(set(a["states/sequence"].tolist()))
    left = _left_out(ex)
    click.echo(f"{out}: {len(a['states/step'])} states from {presses} presses of "
               f"{len(synced)} session(s); {len(a['single/start'])} single-step, "
               f"{len(a['multi/start'])} multi-step examples; left out: {left}"
               + (f"; recording {rrd_path}" if rrd_path else ""))


def _left_out(ex: Extracted) -> str:
    """What extraction left out, in words: presses with an untrusted force first."""
    parts = []
    if ex.untrusted_presses:
        parts.append(f"{count(ex.untrusted_presses, 'press')} saturated/over-range "
                     f"({ex.excluded['saturated_or_over_range']} states)")
    parts += [f"{k} {v}" for k, v in ex.excluded.items()
              if v and k != "saturated_or_over_range"]
    return ", ".join(parts) or "nothing"

"""``pipeline fit-msm``: the click layer over :func:`sim.msm.fit_msm_stage.run_fit_msm`."""

from __future__ import annotations

from pathlib import Path

import click

from core.errors import BadInput
from pipeline.options import ranged, resolve_rrd, rrd_option, seed_option
from sim.msm.fit_msm_params import FitMsmParams

D = FitMsmParams            # the option defaults are its fields', the bounds its BOUNDS
B = D.BOUNDS
OUT = click.Path(dir_okay=False, path_type=Path)
IN = click.Path(exists=True, dir_okay=False, path_type=Path)


class RegionsType(click.ParamType):
    """``RxC`` read into (rows, columns); anything else one line naming ``--regions``."""

    name = "RxC"

    def convert(self, value, param, ctx):  # noqa: ANN001, ANN201 - click's signature
        from sim.msm.msm_regions import parse_regions

        return value if isinstance(value, tuple) else parse_regions(value)


@click.command("fit-msm")
@click.argument("states", type=IN)
@click.option("--out", type=OUT, default=None, help="JSON file for the fitted constants.")
@click.option("--max-sequences", type=ranged(B["max_sequences"]), default=D.max_sequences,
              help="Sequences used (drawn with --seed when the file or fold has more) "
                   f"[default: {D.UNIFORM_SEQUENCES}; with --map every one: a map needs "
                   "every place].")
@click.option("--splits", type=IN, default=None,
              help="Fold manifest of STATES: fit on the training presses of --fold only, so "
                   "the fit never sees that fold's test presses.")
@click.option("--fold", type=ranged(B["fold"]), default=D.fold, show_default=True)
@click.option("--start", nargs=2, type=ranged(B["start"]),
              default=D.start,
              show_default=True,
              help="Starting k_between k_fixed (N/m; the paper's constants).")
@click.option("--contact-radius", type=ranged(B["contact_radius"]),
              default=D.contact_radius,
              help="Share the load among the masses within this radius (m) of the tip "
                   "[default: 0 for lab states (one mass, the paper's n_n = 1); an MSM file's "
                   "own].")
@click.option("--spacing-mm", type=ranged(B["spacing"], 1e3, "mm"), default=D.spacing,
              help="Lab states: the masses' spacing in mm, rounded per axis so the grid covers "
                   "the states' footprint_m exactly [default: the paper's 100/31 = 3.226 mm]. "
                   "An MSM file brings its own grid.")
@click.option("--workers", type=ranged(B["workers"]), default=D.workers,
              help="Processes sharing the sequences (default: the cores this process may use).")
@click.option("--map", "stiffness_map", is_flag=True, default=D.map,
              help="Also fit a stiffness map: a factor per region of --regions on top of the "
                   "uniform constants, shrunk toward 1 by a weight the held-out presses "
                   "choose, each with its uncertainty; written as msm_params.stiffness_map, "
                   "which `simulate --params` carries. Regions without a press within 5 mm "
                   "stay at 1, said in one line.")
@click.option("--regions", type=RegionsType(), default=D.regions,
              help="With --map: RxC regions, R rows along y of C regions along x, over the "
                   "footprint [default: the finest grid whose every region holds a press "
                   "place in its middle: 4x4 for `synth --locations 4x4`].")
@seed_option(D.seed)
@rrd_option
def fit_msm(states: Path, out: Path | None, max_sequences: int | None, splits: Path | None,
            fold: int, start: tuple[float, float], contact_radius: float | None,
            spacing_mm: float | None, workers: int, stiffness_map: bool,
            regions: tuple[int, int] | None,
            seed: int, rrd: Path | None, no_rrd: bool) -> None:
    """Fit the MSM spring constants to measured states (as the paper found 100 and 21 N/m).

    Reads STATES (a phantom.states file: extracted lab states or MSM states; with --splits, its
    fold manifest). Finds (k_between, k_fixed) in [1, 1e5] N/m minimising the mean distance
    between the measured points and the MSM's static response to the measured loads, in the
    phantom frame (see sim/msm/msm_fit.py), on a grid covering the lab states' footprint_m at
    the paper's mass spacing (the paper's 100 mm square where they have none; an MSM file's own
    grid). Prints the constants, the distance beside the start constants' and a still surface's
    (pooled and per press), and says when a constant ends on a bound. Writes --out (when given):
    the constants, the distances and the full MSM parameters (the grid included) as JSON
    (phantom.msm_params, read by `pipeline simulate --params`), and a rerun recording of the
    fitted MSM beside the measured markers (--rrd, default beside --out).
    """
    from sim.msm.fit_msm_params import FitMsmInputs
    from sim.msm.fit_msm_stage import run_fit_msm
    if regions is not None and not stiffness_map:
        raise BadInput("--regions", "is the stiffness map's: give it with --map")
    rrd_path = resolve_rrd(out, rrd, no_rrd) if out is not None else None
    params = FitMsmParams(max_sequences=max_sequences, fold=fold, start=start,
                          contact_radius=contact_radius,
                          spacing=None if spacing_mm is None else spacing_mm * 1e-3,
                          workers=workers, seed=seed, map=stiffness_map, regions=regions)
    outcome = run_fit_msm(FitMsmInputs(states, splits), out, params, rrd_path)
    text = fit_summary(outcome.fit)
    if outcome.map is not None:
        text += "\n" + map_summary(outcome.map)
    click.echo(text + (f"\nwrote {out}" if out else "") + (f", {rrd_path}" if rrd_path else ""))


def fit_summary(result) -> str:  # noqa: ANN001 - FitResult, imported lazily
    """The fit in a few lines: constants, distances against the references, bounds."""
    mm = 1e3
    lines = [f"k_between {result.k_between:.4g} N/m, k_fixed {result.k_fixed:.4g} N/m "
             f"(contact radius {result.contact_radius_m * mm:g} mm) over {result.states} states "
             f"of {result.sequences} sequences" + (f", on {result.grid}" if result.grid else ""),
             f"mean distance {result.mean_distance_m * mm:.3f} mm; start constants "
             f"{result.start_distance_m * mm:.3f} mm; still surface "
             f"{result.still_distance_m * mm:.3f} mm "
             f"({result.mean_distance_m / result.still_distance_m:.0%} of it); nothing moves "
             f"but the tip {result.nothing_moves_distance_m * mm:.3f} mm",
             "per sequence [mm] (fitted / start / still): " + ", ".join(
                 f"{r['sequence']}: {r['fitted_m'] * mm:.2f}/{r['start_m'] * mm:.2f}/"
                 f"{r['still_m'] * mm:.2f}" for r in result.per_sequence)]
    lines += [f"note: {b}: the fit wants a constant outside the physical range"
              for b in result.at_bound]
    return "\n".join(lines)


def map_summary(found) -> str:  # noqa: ANN001 - MapResult, imported lazily
    """The map in a few lines: its factors row by row (y up the page), the weight the
    held-out presses chose, the distance beside the uniform fit's, and the note if any."""
    rows = []
    for i in reversed(range(found.shape[0])):
        rows.append("  " + "  ".join(f"{f:5.2f}" + (f" +- {sd:.2g}" if sd is not None
                                                     else " (held)  ")
                                     for f, sd in zip(found.factors[i], found.sd[i],
                                                      strict=True)))
    lines = [f"stiffness map {found.shape[0]}x{found.shape[1]} over {found.places} press "
             f"places (rows top = largest y; factors on the uniform constants):", *rows,
             f"shrinkage weight {found.weight:g} (held-out presses); mean distance "
             f"{found.mean_distance_m * 1e3:.3f} mm (uniform {found.uniform_distance_m * 1e3:.3f}"
             f" mm) after {found.steps} step(s)"]
    if found.stiffest:
        top = found.stiffest
        lines.append(f"stiffest region centred at ({top['centre_mm'][0]:g}, "
                     f"{top['centre_mm'][1]:g}) mm: {top['factor']:.2f} +- {top['sd']:.2g}; "
                     f"the peak among its neighbours at ({top['peak_mm'][0]:.0f}, "
                     f"{top['peak_mm'][1]:.0f}) mm")
    if found.note:
        lines.append(f"note: {found.note}")
    return "\n".join(lines)

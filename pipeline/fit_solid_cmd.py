"""``pipeline fit-solid``: the click layer over :func:`sim.solid.fit_solid_stage.run_fit_solid`."""

from __future__ import annotations

from pathlib import Path

import click

from pipeline.options import ranged, resolve_rrd, rrd_option
from sim.solid.fit_solid_params import FitSolidParams

D = FitSolidParams          # the option defaults are its fields', the bounds its BOUNDS
B = D.BOUNDS
OUT = click.Path(dir_okay=False, path_type=Path)
IN = click.Path(exists=True, dir_okay=False, path_type=Path)


@click.command("fit-solid")
@click.argument("states", type=IN)
@click.option("--out", type=OUT, default=None, help="JSON file for the fitted solid.")
@click.option("--splits", type=IN, default=None,
              help="Fold manifest of STATES: fit on the training presses of --fold only.")
@click.option("--fold", type=ranged(B["fold"]), default=D.fold, show_default=True)
@click.option("--session", type=click.Path(exists=True, file_okay=False, path_type=Path),
              default=None,
              help="The session folder whose session.toml names the interior ([phantom] "
                   "interior, a NIfTI label volume, and [phantom.labels], each label's "
                   "stiffness ratio or \"fit\") and a curved phantom's shape ([phantom] "
                   "shape) [default: a uniform, flat block].")
@click.option("--msm", type=IN, default=None,
              help="fit-msm's JSON for the same presses: its distance is printed beside the "
                   "solid's.")
@click.option("--thickness-mm", type=ranged(B["thickness"], 1e3, "mm"),
              default=D.thickness * 1e3, show_default=True, help="The block's thickness.")
@click.option("--spacing-mm", type=ranged(B["spacing"], 1e3, "mm"), default=D.spacing * 1e3,
              show_default=True, help="The mesh's node spacing across the footprint.")
@click.option("--layers", type=ranged(B["layers"]), default=D.layers, show_default=True,
              help="Element layers through the thickness (half in its top quarter).")
@click.option("--poisson", type=ranged(B["poisson"]), default=D.poisson, show_default=True,
              help="The Poisson ratio (held; where --fit-poisson starts).")
@click.option("--fit-poisson", is_flag=True, default=D.fit_poisson,
              help="Also fit the Poisson ratio (a new factorisation per step: slower).")
@rrd_option
def fit_solid(states: Path, out: Path | None, splits: Path | None, fold: int,
              session: Path | None, msm: Path | None, thickness_mm: float, spacing_mm: float,
              layers: int, poisson: float, fit_poisson: bool, rrd: Path | None,
              no_rrd: bool) -> None:
    """Fit the solid model of the phantom (finite elements of the block with its interior) to
    measured states.

    Reads STATES (a phantom.states file; with --splits, its fold manifest) and, with
    --session, the interior and the shape its session.toml names. Meshes the block (the
    footprint of the states x --thickness-mm, its top where the tips rest, the bottom fixed to
    the table; a curved phantom's: its shape, each column from the table to the top) with
    trilinear hexahedra (scikit-fem) and fits the block's modulus, how it stiffens with the
    dent, the tip's contact radius, every "fit" label's ratio (and with --fit-poisson the
    Poisson ratio), each with its uncertainty, minimising the distance of every point (markers
    and tip) to the solid's static response to the measured loads. Prints the material and
    the markers' mean distance beside a still surface's (and fit-msm's, with --msm). Writes
    --out (when given): the material, its uncertainties, the block, the mesh, the labels and
    the distances (phantom.solid_params), and a rerun recording (--rrd, default beside --out):
    the interior, the fitted solid's surface beside the measured markers, the residual per
    marker. Refuses in one line an interior that does not cover the block, a label without
    a ratio, a ratio outside 0.1-20.
    """
    from sim.solid.fit_solid_params import FitSolidInputs
    from sim.solid.fit_solid_stage import run_fit_solid
    rrd_path = resolve_rrd(out, rrd, no_rrd) if out is not None else None
    params = FitSolidParams(fold=fold, thickness=thickness_mm * 1e-3, spacing=spacing_mm * 1e-3,
                            layers=layers, poisson=poisson, fit_poisson=fit_poisson)
    outcome = run_fit_solid(FitSolidInputs(states, splits, session, msm), out, params, rrd_path)
    click.echo(solid_summary(outcome) + (f"\nwrote {out}" if out else "")
               + (f", {rrd_path}" if rrd_path else ""))


def solid_summary(outcome) -> str:  # noqa: ANN001 - SolidOutcome, imported lazily
    """The fit in a few lines: the material with its sd, the distances beside the references."""
    fit, m, sd = outcome.fit, outcome.fit.material, outcome.fit.sd
    lines = [f"modulus {m.modulus:.4g} +- {sd['modulus']:.2g} Pa, stiffening "
             f"{m.stiffening:.4g} +- {sd['stiffening']:.2g} 1/m^2, contact radius "
             f"{m.contact_radius * 1e3:.2f} +- {sd['contact_radius'] * 1e3:.2g} mm, reach "
             f"{m.reach * 1e3:.1f} +- {sd['reach'] * 1e3:.2g} mm, Poisson "
             f"{m.poisson:.3f}" + (f" +- {sd['poisson']:.2g}" if "poisson" in sd else " (held)")]
    for k, ratio in enumerate(m.ratios[1:], start=1):
        key = f"ratio_{k}"
        lines.append(f"label {k}: ratio {ratio:.3g}" + (f" +- {sd[key]:.2g} (fitted)"
                                                        if key in sd else " (given)"))
    msm = "" if outcome.msm_mm is None else f"; the MSM fit {outcome.msm_mm:.3f} mm (all points)"
    lines.append(f"mean distance: markers {fit.marker_mm:.3f} mm, tip {fit.tip_mm:.3f} mm, all "
                 f"points {fit.all_mm:.3f} mm; still surface {fit.still_mm:.3f} mm{msm}; "
                 f"{outcome.seconds:.0f} s ({fit.factorisations} factorisations)")
    return "\n".join(lines)

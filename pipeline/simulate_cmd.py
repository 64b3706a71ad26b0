"""``pipeline simulate``: the click layer over :func:`sim.msm.simulate_stage.run_simulate`
(and :func:`~sim.msm.simulate_stage.run_merge`)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from core.errors import BadInput
from pipeline.options import SIZE_MM, Parsed, ranged, resolve_rrd, rrd_option, seed_option
from sim.msm.mould_prior import MOULDS
from sim.msm.msm_prior import PRIOR, PRIOR_DIRECTIONS, PRIOR_LOCATIONS
from sim.msm.msm_protocol import Protocol, parse_shard
from sim.msm.simulate_params import SimulateParams

if TYPE_CHECKING:
    from sim.msm.simulate_stage import Simulation

D = SimulateParams          # the option defaults are its fields', the bounds its BOUNDS
B = D.BOUNDS
OUT = click.Path(dir_okay=False, path_type=Path)
IN = click.Path(exists=True, dir_okay=False, path_type=Path)


def _mm(span: tuple[float, float]) -> str:
    """A range of the prior in m as ``LO-HI`` in mm (its help, its closing line)."""
    return f"{span[0] * 1e3:g}-{span[1] * 1e3:g}"


@click.command()
@click.option("--out", required=True, type=OUT, help="States file to write (HDF5).")
@click.option("--locations", type=ranged(B["locations"]), default=D.locations,
              help=f"Random masses loaded, one per location [default: the paper's "
                   f"{Protocol.locations}; with --prior, {PRIOR_LOCATIONS} per phantom].")
@click.option("--directions", type=ranged(B["directions"]), default=D.directions,
              help=f"Force directions per location: the normal + random ones within "
                   f"--max-angle [default: the paper's {Protocol.directions}; with --prior, "
                   f"{PRIOR_DIRECTIONS}].")
@click.option("--prior", type=ranged(B["prior"]), default=D.prior, show_default=True,
              help="Draw this many phantoms from the prior (sim/msm/msm_prior.py: springs, "
                   f"contact patch, footprint {_mm(PRIOR.side)} mm a side, "
                   f"{PRIOR.markers[0]}-{PRIOR.markers[1]} markers in a grid or "
                   f"scattered {_mm(PRIOR.pitch)} mm apart, some occluded, the press's angle), "
                   "one block of "
                   "--locations x --directions sequences each, sampled at its markers: the "
                   "data one pre-training for every lab learns from (0: one MSM).")
@click.option("--moulds", is_flag=True, default=D.moulds,
              help="With --prior: draw curved moulds instead (sim/msm/mould_prior.py: a dome or "
                   f"a ridge {_mm(MOULDS.height)} mm high over a block "
                   f"{_mm(MOULDS.thickness)} mm thick, the MSM prior's footprints and markers "
                   "on the cap, each press about the place's normal) and press each one's "
                   "solid (linear elasticity with the stiffening law, its modulus set by how deep "
                   "its centre press at 7.5 N goes): what the generic model for curved labs "
                   "learns from. source=\"moulds\"; no --shard.")
@click.option("--steps", type=ranged(B["steps"]), default=D.steps, show_default=True,
              help="Equal force steps up to --fmax.")
@click.option("--fmax", type=ranged(B["fmax"]), default=D.fmax,
              show_default=True,
              help="Largest force (N). Refused when it drives the MSM deeper than its surface "
                   "is wide (its narrower side); states deeper than --thickness are counted.")
@click.option("--size", type=SIZE_MM, default=D.size,
              help="The surface's footprint LxW in mm (along x by y, e.g. 150x80) "
                   "[default: the --layout states' footprint_m, else the --params fit's grid, "
                   "else the paper's 100x100].")
@click.option("--spacing-mm", type=ranged(B["spacing"], 1e3, "mm"), default=D.spacing,
              help="The masses' spacing in mm, rounded per axis so the grid covers the "
                   "footprint exactly [default: the paper's 100/31 = 3.226 mm].")
@click.option("--k-between", type=ranged(B["k_between"]), default=D.k_between, show_default=True,
              help="Between-mass spring constant (N/m).")
@click.option("--k-fixed", type=ranged(B["k_fixed"]), default=D.k_fixed, show_default=True,
              help="Fixed-spring constant (N/m).")
@click.option("--thickness", type=ranged(B["thickness"]),
              default=D.thickness, show_default=True,
              help="The phantom's thickness (m): states whose tip goes deeper are counted in "
                   "the closing line.")
@click.option("--params", "params_file", type=IN, default=None,
              help="Spring constants and contact radius from `pipeline fit-msm --out` "
                   "(phantom.msm_params JSON): overrides --k-between, --k-fixed and "
                   "--contact-radius, and brings the grid they were fitted on (a --size, "
                   "--spacing-mm or --layout footprint asking for another is refused).")
@click.option("--solid", type=IN, default=None,
              help="Simulate the solid model of `pipeline fit-solid --out` (phantom.solid_params "
                   "JSON: the block with its interior, fitted to a lab) instead of the MSM, at "
                   "the --layout states' markers (needed): the same protocol (--locations, "
                   "--directions, --steps, --fmax, --max-angle, --seed, --shard), its places "
                   "the top face's mesh nodes inside the markers' bounding box; source=\"solid\".")
@click.option("--contact-radius", type=ranged(B["contact_radius"]),
              default=D.contact_radius, show_default=True,
              help="The load is shared by every mass within this radius (m) of the loaded "
                   "one: the indenter's contact patch (0: one mass, the paper's n_n = 1).")
@click.option("--layout", type=IN, default=None,
              help="Lab states file (from `pipeline extract`): size the surface to its "
                   "footprint_m, sample the MSM at its markers' rest positions (any number, "
                   "named by its point_names), with the loaded patch's centre as the tip (the "
                   "last point), and load only inside the markers' bounding box: the graph the "
                   "network is fine-tuned on.")
@click.option("--max-angle", "max_angle_deg", type=ranged(B["max_angle_deg"]),
              default=D.max_angle_deg,
              show_default=True,
              help="Largest angle of a force direction from the normal (degrees).")
@click.option("--tol", type=ranged(B["tol"]),
              default=D.tol, show_default=True,
              help="Static tolerance: largest force left on any mass (N) of the float64 "
                   "solution. Points are stored as float32 (~1e-8 m quantisation at 0.1 m), "
                   "which leaves a residual of ~1e-6 to 1e-5 N whatever --tol is; both are "
                   "stored (max_residual_N, stored_residual_N).")
@click.option("--workers", type=ranged(B["workers"]), default=D.workers,
              help="Processes (default: the cores this process may use).")
@click.option("--shard", type=Parsed("I/N", parse_shard, keep_text=True), default=D.shard,
              help="Simulate only block I (0-based) of N contiguous blocks of locations.")
@click.option("--merge", is_flag=True,
              help="Join the SHARDS files of one sharded run into --out instead of simulating.")
@click.option("--rrd-sequences", type=ranged(B["rrd_sequences"]), default=D.rrd_sequences,
              show_default=True,
              help="Sequences shown in the recording.")
@click.argument("shards", nargs=-1, type=IN)
@seed_option(D.seed)
@rrd_option
def simulate(out: Path, locations: int | None, directions: int | None, prior: int,
             moulds: bool, steps: int, fmax: float,
             size: tuple[float, float] | None, spacing_mm: float | None,
             k_between: float, k_fixed: float, thickness: float, params_file: Path | None,
             solid: Path | None, contact_radius: float, layout: Path | None,
             max_angle_deg: float, tol: float,
             workers: int, shard: str | None, merge: bool, rrd_sequences: int,
             shards: tuple[Path, ...], seed: int, rrd: Path | None, no_rrd: bool) -> None:
    """Generate the paper's mass-spring-model (MSM) training states.

    Reads nothing (or --params, --layout, --solid; with --merge, the SHARDS files). Writes --out, a
    phantom.states HDF5 file laid out like extracted lab states: states/points (S, N, 3) in m
    (every mass, or with --layout the lab's markers then the tip), tip (the loaded mass),
    force, force_vector, step, sequence (= location * directions + direction), location;
    single-step examples (t, t+1) and 15 random multi-step pairs per sequence; root attributes
    source="msm", msm_params (the grid too), footprint_m, protocol, solver, max_residual_N and
    stored_residual_N (with --layout also layout and point_names). Each state is the static
    equilibrium of the surface MSM (the paper's: 32 x 32 masses over 100 x 100 mm, 100 and
    21 N/m; any LxW footprint at the paper's mass spacing with --size or --layout) solved
    directly to --tol, not by explicit integration (max_residual_N: the largest force left on
    any mass of any state). Points are
    stored as float32: their ~1e-8 m quantisation leaves ~1e-6 to 1e-5 N on a mass
    (stored_residual_N), a floor no --tol lowers. Also writes a rerun recording of a few
    sequences (--rrd, default beside --out). The surface has no floor: states whose tip goes
    deeper than the phantom's thickness (--thickness) are counted in the closing line, and an
    --fmax that drives the MSM deeper than its surface is wide is refused before simulating.

    \b
    With --prior B: B phantoms drawn from the prior instead of one MSM (one pre-training
    for every lab): states/points holds the largest marker count then the tip, the slots a
    phantom lacks valid False; states/phantom and phantoms/* record each phantom's draw.
    With --prior B --moulds: B curved moulds' solids instead (their cap, height, thickness,
    modulus, stiffening, reach and centre depth in phantoms/*), in the same layout.

    \b
    Sharded (cluster jobs), then merged into the same arrays as one run:
      pipeline simulate --shard 0/2 --out part0.h5   (same options in every shard)
      pipeline simulate --shard 1/2 --out part1.h5
      pipeline simulate --merge part0.h5 part1.h5 --out MSM.h5
    """
    from sim.msm.simulate_params import SimulateInputs
    from sim.msm.simulate_stage import run_merge, run_simulate

    rrd_path = resolve_rrd(out, rrd, no_rrd)
    params = SimulateParams(
        locations=locations, directions=directions, steps=steps, fmax=fmax,
        max_angle_deg=max_angle_deg, seed=seed, contact_radius=contact_radius,
        k_between=k_between, k_fixed=k_fixed, size=size,
        spacing=None if spacing_mm is None else spacing_mm * 1e-3, tol=tol, workers=workers,
        shard=shard, thickness=thickness, rrd_sequences=rrd_sequences, prior=prior,
        moulds=moulds)
    if merge:
        if shard is not None:
            raise BadInput(None, "--merge and --shard exclude each other")
        run = run_merge(shards, out, params, rrd_path)
        what = f"merged {len(shards)} shards"
    else:
        if shards:
            raise BadInput(None, "SHARDS are only read with --merge")
        run = run_simulate(SimulateInputs(layout=layout, params_file=params_file, solid=solid),
                           out, params, rrd_path)
        what = _what(run, prior, moulds)
    a = run.arrays
    click.echo(f"{out}: {len(a['states/step'])} states, {len(a['single/start'])} single-step and "
               f"{len(a['multi/start'])} multi-step examples; {what} in {run.seconds:.1f} s; "
               + _depths(run, thickness, bool(prior), moulds)
               + (f"; recording {rrd_path}" if rrd_path else ""))


def _what(run: Simulation, prior: int, moulds: bool) -> str:
    """The closing line's words on what was simulated."""
    sim = run.sim
    if moulds:
        return (f"simulated {prior} moulds' solids (linear elasticity, one factorisation each) "
                f"with {run.workers} workers")
    if sim is None:
        return "simulated the solid (linear elasticity, one factorisation)"
    unit = "phantoms of the prior" if prior else "locations"
    return (f"simulated {len(sim.locations)} {unit} with {run.workers} workers (max residual "
            f"{sim.max_residual:.2g} N solved, {sim.stored_residual:.2g} N as stored in "
            "float32)")


def _depths(run: Simulation, thickness: float, prior: bool, moulds: bool = False) -> str:
    """The closing line's words on how deep the states go: against the phantom's thickness,
    or, for a prior's phantoms, against the depth range their centre presses were drawn in
    (a mould's measured from its cap, not from z = 0: its range alone)."""
    deep, deepest = run.beyond_thickness
    if moulds:
        return (f"each mould's centre press at 7.5 N drawn {_mm(MOULDS.depth_m)} mm deep, at "
                f"most {MOULDS.column_share:g} of the column under it (phantoms/depth)")
    if prior:
        return (f"deepest {deepest * 1e3:.1f} mm (each phantom's centre press at 7.5 N drawn "
                f"{_mm(PRIOR.depth_m)} mm deep)")
    if deep:
        return (f"{deep} states deeper than the phantom's {thickness * 1e3:g} mm thickness "
                f"(deepest {deepest * 1e3:.1f} mm: lower --fmax or stiffen the springs to "
                "stay inside it)")
    return f"deepest {deepest * 1e3:.1f} mm, within the phantom's {thickness * 1e3:g} mm"

"""``pipeline simulate`` and ``pipeline fit-msm``: click layers over :mod:`sim.msm_dataset`
and :mod:`sim.msm_fit`."""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path

import click

from pipeline.options import resolve_rrd, rrd_option, seed_option

OUT = click.Path(dir_okay=False, path_type=Path)
IN = click.Path(exists=True, dir_okay=False, path_type=Path)


@click.command()
@click.option("--out", required=True, type=OUT, help="States file to write (HDF5).")
@click.option("--locations", type=click.IntRange(1), default=100, show_default=True,
              help="Random masses loaded, one per location.")
@click.option("--directions", type=click.IntRange(1), default=11, show_default=True,
              help="Force directions per location: the normal + random ones within 45 deg.")
@click.option("--steps", type=click.IntRange(1), default=15, show_default=True,
              help="Equal force steps up to --fmax.")
@click.option("--fmax", type=float, default=7.5, show_default=True, help="Largest force (N).")
@click.option("--k-between", type=float, default=100.0, show_default=True,
              help="Between-mass spring constant (N/m).")
@click.option("--k-fixed", type=float, default=21.0, show_default=True,
              help="Fixed-spring constant (N/m).")
@click.option("--tol", type=float, default=1e-6, show_default=True,
              help="Static tolerance: largest force left on any mass (N) of the float64 "
                   "solution. Points are stored as float32 (~1e-8 m quantisation at 0.1 m), "
                   "which leaves a residual of ~1e-6 to 1e-5 N whatever --tol is; both are "
                   "stored (max_residual_N, stored_residual_N).")
@click.option("--workers", type=click.IntRange(0), default=0,
              help="Processes (default: the cores this process may use).")
@click.option("--shard", metavar="I/N", default=None,
              help="Simulate only block I (0-based) of N contiguous blocks of locations.")
@click.option("--merge", is_flag=True,
              help="Join the SHARDS files of one sharded run into --out instead of simulating.")
@click.option("--rrd-sequences", type=click.IntRange(0), default=4, show_default=True,
              help="Sequences shown in the recording.")
@click.argument("shards", nargs=-1, type=IN)
@seed_option
@rrd_option
def simulate(out: Path, locations: int, directions: int, steps: int, fmax: float,
             k_between: float, k_fixed: float, tol: float, workers: int, shard: str | None,
             merge: bool, rrd_sequences: int, shards: tuple[Path, ...], seed: int,
             rrd: Path | None, no_rrd: bool) -> None:
    """Generate the paper's mass-spring-model (MSM) training states.

    Reads nothing (or, with --merge, the SHARDS files). Writes --out, a phantom.states HDF5
    file laid out like extracted lab states: states/points (S, 1024, 3) in m, tip (the loaded
    mass), force, force_vector, step, sequence (= location * directions + direction),
    location; single-step examples (t, t+1) and 15 random multi-step pairs per sequence; root
    attributes source="msm", msm_params, protocol, solver, max_residual_N and
    stored_residual_N. Each state is the static equilibrium of the surface MSM (32 x 32
    masses over 100 x 100 mm, 100 and 21 N/m) solved directly to --tol, not by explicit
    integration (max_residual_N: the largest force left on any mass of any state). Points are
    stored as float32: their ~1e-8 m quantisation leaves ~1e-6 to 1e-5 N on a mass
    (stored_residual_N), a floor no --tol lowers. Also writes a rerun recording of a few
    sequences (--rrd, default beside --out).

    \b
    Sharded (cluster jobs), then merged into the same arrays as one run:
      pipeline simulate --shard 0/2 --out part0.h5   (same options in every shard)
      pipeline simulate --shard 1/2 --out part1.h5
      pipeline simulate --merge part0.h5 part1.h5 --out MSM.h5
    """
    from sim.msm import MSM, MSMParams
    from sim.msm_dataset import Protocol, default_workers, generate, merge_shards, parse_shard
    from sim.msm_view import write_simulate_recording

    rrd_path = resolve_rrd(out, rrd, no_rrd)
    started = time.perf_counter()
    if merge:
        if shard is not None:
            raise click.UsageError("--merge and --shard exclude each other")
        arrays = merge_shards(shards, out)
        params = _params_of(out)
        what = f"merged {len(shards)} shards"
    else:
        if shards:
            raise click.UsageError("SHARDS are only read with --merge")
        params = MSMParams(k_between=k_between, k_fixed=k_fixed)
        protocol = Protocol(locations=locations, directions=directions, steps=steps,
                            fmax=fmax, seed=seed)
        shard_ij = parse_shard(shard) if shard else None
        n_workers = workers or default_workers()
        sim, arrays = generate(out, protocol, params, tol=tol, workers=n_workers, shard=shard_ij,
                          command_params={**asdict(protocol), "k_between": k_between,
                                          "k_fixed": k_fixed, "tol": tol, "shard": shard})
        what = (f"simulated {len(sim.locations)} locations with {n_workers} workers "
                f"(max residual {sim.max_residual:.2g} N solved, "
                f"{sim.stored_residual:.2g} N as stored in float32)")
    elapsed = time.perf_counter() - started
    if rrd_path is not None:
        write_simulate_recording(rrd_path, arrays, MSM(params).triangles(), rrd_sequences)
    n_states, n_single, n_multi = _counts(out)
    click.echo(f"{out}: {n_states} states, {n_single} single-step and {n_multi} multi-step "
               f"examples; {what} in {elapsed:.1f} s"
               + (f"; recording {rrd_path}" if rrd_path else ""))


@click.command("fit-msm")
@click.argument("states", type=IN)
@click.option("--out", type=OUT, default=None, help="JSON file for the fitted constants.")
@click.option("--max-sequences", type=click.IntRange(1), default=10, show_default=True,
              help="Sequences used (drawn with --seed when the file has more).")
@click.option("--start", nargs=2, type=float, default=(100.0, 21.0), show_default=True,
              help="Starting k_between k_fixed (N/m).")
@seed_option
def fit_msm(states: Path, out: Path | None, max_sequences: int,
            start: tuple[float, float], seed: int) -> None:
    """Fit the MSM spring constants to measured states (as the paper found 100 and 21 N/m).

    Reads STATES (a phantom.states file: extracted lab states or MSM states). Finds
    (k_between, k_fixed) minimising the mean distance between the measured points and the
    MSM's static response to the measured loads (see sim/msm_fit.py for how lab points are
    placed on the grid). Prints a one-line summary, and writes --out (when given): the
    constants, the distances and the full MSM parameters as JSON.
    """
    from core.atomic import atomic_output
    from core.provenance import make_provenance
    from data_schema.json_docs import MSM_PARAMS, validate_json_doc
    from sim.msm_fit import fit_msm as run_fit
    from sim.msm_fit import read_measured

    sequences, params = read_measured(states, max_sequences=max_sequences, seed=seed)
    result = run_fit(sequences, params, start=start)
    record = {
        "schema": MSM_PARAMS.name, "schema_version": MSM_PARAMS.version,
        **asdict(result), "msm_params": {**params.as_dict(), "k_between": result.k_between,
                                         "k_fixed": result.k_fixed},
        "provenance": make_provenance("fit-msm", {"max_sequences": max_sequences,
                                                  "start": list(start), "seed": seed},
                                      inputs=[states]),
    }
    text = json.dumps(record, indent=2, allow_nan=False)
    if out is not None:
        with atomic_output(out) as tmp:
            tmp.write_text(text + "\n")
            validate_json_doc(tmp, MSM_PARAMS)
    click.echo(f"k_between {result.k_between:.4g} N/m, k_fixed {result.k_fixed:.4g} N/m: mean "
               f"distance {result.mean_distance_m * 1e3:.4g} mm (start "
               f"{result.start_distance_m * 1e3:.4g} mm) over {result.states} states of "
               f"{result.sequences} sequences" + (f"; wrote {out}" if out else ""))


def _params_of(path: Path):  # noqa: ANN202 - MSMParams, imported lazily
    import h5py

    from sim.msm import MSMParams

    with h5py.File(path, "r") as f:
        return MSMParams(**json.loads(f.attrs["msm_params"]))


def _counts(path: Path) -> tuple[int, int, int]:
    import h5py

    with h5py.File(path, "r") as f:
        return len(f["states/step"]), len(f["single/start"]), len(f["multi/start"])

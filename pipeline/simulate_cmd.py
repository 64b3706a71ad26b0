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
@click.option("--params", "params_file", type=IN, default=None,
              help="Spring constants and contact radius from `pipeline fit-msm --out` "
                   "(phantom.msm_params JSON): overrides --k-between, --k-fixed and "
                   "--contact-radius.")
@click.option("--contact-radius", type=float, default=0.0, show_default=True,
              help="The load is shared by every mass within this radius (m) of the loaded "
                   "one: the indenter's contact patch (0: one mass, the paper's n_n = 1).")
@click.option("--layout", type=IN, default=None,
              help="Lab states file (from `pipeline extract`): sample the MSM at its markers' "
                   "rest positions, with the loaded patch's centre as the tip (the last "
                   "point), and load only inside the markers' footprint: the graph the "
                   "network is fine-tuned on.")
@click.option("--max-angle", type=click.FloatRange(0, 90), default=45.0, show_default=True,
              help="Largest angle of a force direction from the normal (degrees).")
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
             k_between: float, k_fixed: float, params_file: Path | None,
             contact_radius: float, layout: Path | None, max_angle: float, tol: float,
             workers: int, shard: str | None, merge: bool, rrd_sequences: int,
             shards: tuple[Path, ...], seed: int, rrd: Path | None, no_rrd: bool) -> None:
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
    from sim.msm_dataset import Protocol, generate, lab_layout, merge_shards, parse_shard
    from sim.msm_view import write_simulate_recording
    from sim.workers import default_workers

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
        if params_file is not None:
            k_between, k_fixed, contact_radius = _fitted(params_file)
        params = MSMParams(k_between=k_between, k_fixed=k_fixed)
        protocol = Protocol(locations=locations, directions=directions, steps=steps,
                            fmax=fmax, max_angle_deg=max_angle, seed=seed,
                            contact_radius=contact_radius)
        shard_ij = parse_shard(shard) if shard else None
        n_workers = workers or default_workers()
        inputs = [p for p in (params_file, layout) if p is not None]
        sim, arrays = generate(out, protocol, params, tol=tol, workers=n_workers, shard=shard_ij,
                               command_params={**asdict(protocol), "k_between": k_between,
                                               "k_fixed": k_fixed, "tol": tol, "shard": shard,
                                               "layout": str(layout) if layout else None},
                               layout=lab_layout(layout) if layout else None, inputs=inputs)
        what = (f"simulated {len(sim.locations)} locations with {n_workers} workers "
                f"(max residual {sim.max_residual:.2g} N solved, "
                f"{sim.stored_residual:.2g} N as stored in float32)")
    elapsed = time.perf_counter() - started
    if rrd_path is not None:
        triangles = MSM(params).triangles() if arrays["states/points"].shape[1] == MSM(params).N \
            else None
        write_simulate_recording(rrd_path, arrays, triangles, rrd_sequences)
    n_states, n_single, n_multi = _counts(out)
    click.echo(f"{out}: {n_states} states, {n_single} single-step and {n_multi} multi-step "
               f"examples; {what} in {elapsed:.1f} s"
               + (f"; recording {rrd_path}" if rrd_path else ""))


@click.command("fit-msm")
@click.argument("states", type=IN)
@click.option("--out", type=OUT, default=None, help="JSON file for the fitted constants.")
@click.option("--max-sequences", type=click.IntRange(1), default=10, show_default=True,
              help="Sequences used (drawn with --seed when the file or fold has more).")
@click.option("--splits", type=IN, default=None,
              help="Fold manifest of STATES: fit on the training presses of --fold only, so "
                   "the fit never sees that fold's test presses.")
@click.option("--fold", type=click.IntRange(0), default=0, show_default=True)
@click.option("--start", nargs=2, type=float, default=(100.0, 21.0), show_default=True,
              help="Starting k_between k_fixed (N/m; the paper's constants).")
@click.option("--contact-radius", type=click.FloatRange(0, 0.05), default=None,
              help="Share the load among the masses within this radius (m) of the tip "
                   "[default: 0 for lab states (one mass, the paper's n_n = 1); an MSM file's "
                   "own].")
@click.option("--workers", type=click.IntRange(0), default=0,
              help="Processes sharing the sequences (default: the cores this process may use).")
@seed_option
@rrd_option
def fit_msm(states: Path, out: Path | None, max_sequences: int, splits: Path | None,
            fold: int, start: tuple[float, float], contact_radius: float | None,
            workers: int, seed: int, rrd: Path | None, no_rrd: bool) -> None:
    """Fit the MSM spring constants to measured states (as the paper found 100 and 21 N/m).

    Reads STATES (a phantom.states file: extracted lab states or MSM states; with --splits,
    its fold manifest). Finds (k_between, k_fixed) in [1, 1e5] N/m minimising the mean
    distance between the measured points and the MSM's static response to the measured loads,
    in the phantom frame (see sim/msm_fit.py). Prints the constants, the distance beside the
    start constants' and a still surface's (pooled and per press), and says when a constant
    ends on a bound. Writes --out (when given): the constants, the distances and the full MSM
    parameters as JSON (phantom.msm_params, read by `pipeline simulate --params`), and a
    rerun recording of the fitted MSM beside the measured markers (--rrd, default beside
    --out).
    """
    from core.atomic import atomic_output
    from core.provenance import make_provenance
    from data_schema.json_docs import MSM_PARAMS, validate_json_doc
    from sim.msm_fit import fit_msm as run_fit
    from sim.msm_fit import read_measured
    from sim.msm_fit_view import write_fit_recording
    from sim.workers import default_workers

    rrd_path = resolve_rrd(out, rrd, no_rrd) if out is not None else None
    only = _training_sequences(states, splits, fold) if splits else None
    sequences, params = read_measured(states, max_sequences=max_sequences, seed=seed,
                                      contact_radius=contact_radius, only=only)
    radius = sequences[0].contact_radius
    result = run_fit(sequences, params, start=start, workers=workers or default_workers())
    record = {
        "schema": MSM_PARAMS.name, "schema_version": MSM_PARAMS.version,
        **asdict(result), "msm_params": {**params.as_dict(), "k_between": result.k_between,
                                         "k_fixed": result.k_fixed},
        "provenance": make_provenance("fit-msm", {"max_sequences": max_sequences,
                                                  "start": list(start), "seed": seed,
                                                  "splits": str(splits) if splits else None,
                                                  "fold": fold, "contact_radius": radius},
                                      inputs=[states] + ([splits] if splits else [])),
    }
    text = json.dumps(record, indent=2, allow_nan=False)
    if out is not None:
        with atomic_output(out) as tmp:
            tmp.write_text(text + "\n")
            validate_json_doc(tmp, MSM_PARAMS)
    if rrd_path is not None:
        write_fit_recording(rrd_path, params, result, sequences)
    click.echo(fit_summary(result) + (f"\nwrote {out}" if out else "")
               + (f", {rrd_path}" if rrd_path else ""))


def fit_summary(result) -> str:  # noqa: ANN001 - FitResult, imported lazily
    """The fit in a few lines: constants, distances against the references, bounds."""
    mm = 1e3
    lines = [f"k_between {result.k_between:.4g} N/m, k_fixed {result.k_fixed:.4g} N/m "
             f"(contact radius {result.contact_radius_m * mm:g} mm) over {result.states} states "
             f"of {result.sequences} sequences",
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


def _training_sequences(states: Path, splits: Path, fold: int):  # noqa: ANN202 - np.ndarray
    """The sequence ids of a fold's training presses (a manifest grouped by sequence)."""
    import numpy as np

    from core.errors import BadInput
    from data_schema.json_docs import validate_folds

    doc = validate_folds(splits)
    if doc.get("group_by") != "sequence":
        raise BadInput(splits, "fit-msm --splits needs a manifest grouped by sequence (press)")
    if not 0 <= fold < len(doc["folds"]):
        raise BadInput(splits, f"--fold {fold}: it has {len(doc['folds'])} folds")
    return np.asarray(doc["folds"][fold]["train"]["groups"], dtype=np.int64)


def _fitted(path: Path) -> tuple[float, float, float]:
    """k_between, k_fixed (N/m) and the contact radius (m) of a fit-msm JSON document."""
    from data_schema.json_docs import MSM_PARAMS, validate_json_doc

    doc = validate_json_doc(path, MSM_PARAMS)
    return doc["k_between"], doc["k_fixed"], float(doc.get("contact_radius_m", 0.0))


def _params_of(path: Path):  # noqa: ANN202 - MSMParams, imported lazily
    import h5py

    from sim.msm import MSMParams

    with h5py.File(path, "r") as f:
        return MSMParams(**json.loads(f.attrs["msm_params"]))


def _counts(path: Path) -> tuple[int, int, int]:
    import h5py

    with h5py.File(path, "r") as f:
        return len(f["states/step"]), len(f["single/start"]), len(f["multi/start"])

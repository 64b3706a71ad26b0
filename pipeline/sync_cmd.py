"""``pipeline sync``: the click layer over :func:`sync.sync_stage.run_sync`
(the math: :mod:`sync.sync`)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click
import numpy as np

from core.text import count
from pipeline.options import OneOf, ranged, resolve_rrd, rrd_option
from sync.sync_params import CLOCKS, SyncParams

D = SyncParams              # the option defaults are its fields', the bounds its BOUNDS

if TYPE_CHECKING:
    from sync.sync import SyncResult


@click.command()
@click.argument("mcap", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--out", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Synced HDF5 file to write (schema phantom.synced).")
@click.option("--clock", type=OneOf(CLOCKS), default=D.clock,
              show_default=True,
              help="Clock alignment: trigger pulses, the tip motion against the force (data), "
                   "or trigger when recorded (auto).")
@click.option("--max-gap-ms", type=ranged(D.BOUNDS["max_gap_s"], 1e3, "ms"),
              default=D.max_gap_s * 1e3,
              show_default=True,
              help="Fill marker gaps up to this long; longer ones stay NaN and flagged.")
@click.option("--margin-s", type=ranged(D.BOUNDS["margin_s"]), default=D.margin_s,
              show_default=True,
              help="Unloaded frames kept before contact onset and after release.")
@click.option("--location-radius-mm", type=ranged(D.BOUNDS["location_radius_m"], 1e3, "mm"),
              default=D.location_radius_m * 1e3, show_default=True,
              help="Presses whose contact points are closer share a location id.")
@rrd_option
def sync(mcap: Path, out: Path, clock: str, max_gap_ms: float, margin_s: float,
         location_radius_mm: float, rrd: Path | None, no_rrd: bool) -> None:
    """Synchronise an ingested session into one record per press.

    Reads MCAP (from `pipeline ingest`: mocap markers, pivot recording, force log, ATI
    calibration, trigger). Fits the indenter cluster in every frame and calibrates its tip from
    the pivot recording, tares the force from the unloaded start of the log and re-tares it
    from the rest next to every press (bias creep), aligns the logger clock to the mocap clock
    (offset and drift, from the trigger or from the data; auto falls back to the data when the
    trigger channel is dead), resamples the force onto the mocap frames with an anti-aliasing
    filter, fills short marker gaps, and splits the session into presses with location ids
    (presses cut off by the end of a recording are left out and counted). The data clock
    searches every offset up to the longer recording's length and is checked (offset
    uncertainty, drift within 200 ppm, force rising with the tip's depth in 80 % of presses):
    a lock that fails is refused. Frames made of gauge voltages on the amplifier's rail (the
    .cal's OutputRange) or beyond the sensor's rated load are flagged and counted; extract
    leaves their presses out. Writes --out (HDF5:
    per press the time, the phantom markers + tip, force vector and magnitude, tip depth and
    quality flags; the calibration results and their uncertainty; session.toml's [phantom]
    layout, for extract; provenance) and a rerun recording of the alignment and the tip
    (--rrd, default beside --out). Any number (>= 4) of phantom markers. A flat phantom's
    depth is measured from its markers' rest plane, and markers more than 1 mm RMS off it are
    refused as curved; a phantom whose session.toml names a shape ([phantom] shape) has its
    markers registered to it (each marker's residual in the summary and the recording; one
    resting more than 2 mm off it refused by name) and each press's depth measured along the
    surface normal where its tip touched. Nothing is written on bad input.
    """
    from sync.sync_stage import run_sync

    params = SyncParams(clock=clock, max_gap_s=max_gap_ms * 1e-3, margin_s=margin_s,
                        location_radius_m=location_radius_mm * 1e-3)
    rrd_path = resolve_rrd(out, rrd, no_rrd)
    r = run_sync(mcap, out, params, rrd_path)
    c = r.clock
    locations = len({p.press.location for p in r.presses})
    cut = f" ({r.presses_cut_off} cut off by a recording's end, left out)" if \
        r.presses_cut_off else ""
    if r.holes:
        cut += (f" ({count(len(r.holes), 'hole')} in the streams; "
                f"{count(r.presses_in_holes, 'press')} touching one left out)")
    click.echo(f"{out}: {len(r.presses)} presses{cut} at {locations} locations; clock ({c.method}) "
               f"offset {c.offset_s * 1e3:.3f} +- {c.offset_sd_s * 1e3:.3f} ms, drift "
               f"{c.drift_ppm:.2f} +- {c.drift_sd_ppm:.2f} ppm; tip pivot RMS "
               f"{r.pivot.rms * 1e3:.3f} mm{_registration(r)}{_force_flags(r)}"
               + (f"; recording {rrd_path}" if rrd_path else ""))


def _registration(r: SyncResult) -> str:
    """A curved phantom's words: how far its markers rest off the registered shape."""
    if r.registration is None:
        return ""
    res = np.abs(r.registration.residual)
    k = int(np.nanargmax(res))
    return (f"; markers registered to the shape within {res[k] * 1e3:.2f} mm (largest "
            f"{r.point_names[k]}; RMS {np.sqrt(np.nanmean(res ** 2)) * 1e3:.2f} mm)")


def _force_flags(r: SyncResult) -> str:
    """The closing message's words on presses whose force cannot be trusted (flagged, and
    left out by extract)."""
    from sync.sync import flagged_presses

    words = []
    rail, rail_frames = flagged_presses(r.presses, "saturated")
    if rail:
        words.append(f"{count(rail, 'press')} with a gauge on the amplifier's rail "
                     f"({r.rail_samples:,} log samples, {rail_frames:,} frames)")
    over, over_frames = flagged_presses(r.presses, "over_range")
    if over:
        words.append(f"{count(over, 'press')} with a force beyond the sensor's rated load "
                     f"({over_frames:,} frames)")
    return "".join(f"; {w}: flagged, left out by extract" for w in words)

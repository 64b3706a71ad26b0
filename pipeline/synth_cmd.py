"""``pipeline synth``: the click layer over :func:`sim.twin.synth_stage.run_synth`."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import click

from pipeline.options import OneOf, Parsed, ranged, resolve_rrd, rrd_option, seed_option
from sim.twin.marker_layout import parse_layout, parse_size
from sim.twin.material_regions import (
    INCLUSION_FORM,
    LAYER_FORM,
    RADIUS_RANGE_M,
    RATIO_RANGE,
    parse_inclusion,
    parse_layer,
)
from sim.twin.phantom import PhantomSpec
from sim.twin.synth_params import RANDOM_PLACES, SynthParams
from sim.twin.twin_scene import FORCE_FILES, MAX_GRID_PLACES, parse_locations

D = SynthParams             # the option defaults are its fields', the bounds its BOUNDS
B = D.BOUNDS
# The twin lab's options, which `pipeline demo` passes on to synth and so takes alike; each
# refused as it is parsed, with the bounds the twin checks (sim/twin/synth_params.py).
MARKERS = Parsed("RxC|scattered:N", parse_layout, keep_text=True)
MARKER_PITCH_MM = ranged(B["marker_pitch_mm"])
SIZE = Parsed("LxW", parse_size, keep_text=True)
MOCAP_RATE = ranged(B["rate_hz"])
THICKNESS_MM = PhantomSpec.size[2] * 1e3
INCLUSION = Parsed(INCLUSION_FORM, parse_inclusion, keep_text=True)
LAYER = Parsed(LAYER_FORM, parse_layer, keep_text=True)


class Locations(click.ParamType):
    """``--locations N`` (places drawn at random, as an int) or ``RxC`` (a grid, as its
    text), each refused in one line as it is parsed."""

    name = "N|RxC"

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> int | str:
        """``value`` as N or the grid's text, or BadInput naming the option."""
        if isinstance(value, int) or str(value).strip().isdigit():
            return int(ranged(RANDOM_PLACES).convert(value, param, ctx))   # whole: an int
        parse_locations(str(value))
        return str(value).strip()


@click.command()
@click.argument("out_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--locations", type=Locations(), default=D.locations, show_default=True,
              help=f"Indentation places on the phantom: N ({RANDOM_PLACES.min:g} to "
                   f"{RANDOM_PLACES.max:g}) drawn at random, at least 15 mm apart, or RxC "
                   f"(at most {MAX_GRID_PLACES} places): R rows of C "
                   "places (rows along +x, stacked along +y) spread evenly over the nodes a "
                   "press may target (two lattice spacings clear of every marker, 20 mm inside "
                   "the edges: 4x4 at most with the default markers), numbered row-major.")
@click.option("--repeats", type=ranged(B["repeats"]), default=D.repeats, show_default=True,
              help="Presses per location (in rounds over the locations).")
@click.option("--press-seconds", type=ranged(B["press_seconds"]),
              default=D.press_seconds,
              help="Mean duration of one press cycle in s (default about 6 s).")
@click.option("--pivot-seconds", type=ranged(B["pivot_seconds"]),
              default=D.pivot_seconds,
              show_default=True, help="Length of the pivot-calibration recording (s).")
@click.option("--trigger/--no-trigger", default=D.trigger, show_default=True,
              help="Record sync pulses (force-log column 'trigger', QTM EVENT 'Trigger').")
@click.option("--offset", "offset_s", type=ranged(B["offset_s"]),
              default=D.offset_s,
              help="Logger clock offset in s (default: drawn, 0.3-3 s, either sign; "
                   "giving it changes no other random choice).")
@click.option("--drift", "drift_ppm",
              type=ranged(B["drift_ppm"]), default=D.drift_ppm,
              help="Logger clock drift in ppm (default: drawn, 10-60 ppm, either sign; "
                   "giving it changes no other random choice).")
@click.option("--force-via", type=OneOf(FORCE_FILES), default=D.force_via,
              show_default=True,
              help="logger: the Speedgoat log on its own clock (force.csv, force.mat); "
                   "analog: the Nano17 through the mocap's analog board, on the mocap clock "
                   "(indentation.c3d with markers and analog channels, indentation_a.tsv); "
                   "plate: a force plate under the phantom, on the mocap clock (the QTM "
                   "force-plate export indentation_f_1.tsv: the true force and its moment "
                   "with the plate's noise, the centre of pressure; no Nano17).")
@click.option("--force-file", type=OneOf(dict.fromkeys(f for fs in FORCE_FILES.values()
                                                      for f in fs)),
              default=D.force_file,
              help="The force file session.toml names: csv (default) or mat with --force-via "
                   "logger; tsv (default, the QTM analog export) or c3d (then also the mocap "
                   "file) with --force-via analog; tsv (the plate's export) with --force-via "
                   "plate. Every file of a route is written.")
@click.option("--markers", type=MARKERS, default=D.markers, show_default=True,
              help="Phantom markers: a grid RxC (R rows along +x, C markers each, centred, "
                   "named row-major P00, P01, ...) or scattered:N (N markers at random "
                   "lattice nodes, at least 10 mm apart and 10 mm inside the edges; P00 -> P01 "
                   "along +x, written to session.toml as [phantom] x_axis and anchor).")
@click.option("--marker-pitch", "marker_pitch_mm", type=MARKER_PITCH_MM,
              default=D.marker_pitch_mm,
              show_default=True,
              help="Distance between neighbouring grid markers in mm (at least 10).")
@click.option("--size", type=SIZE, default=D.size, show_default=True,
              help="The block's footprint LxW in mm (L along +x; 40 to 300 each; 32 mm thick).")
@click.option("--inclusion", "inclusions", type=INCLUSION, multiple=True,
              help="A sphere of another silicone, X,Y,DEPTH,RADIUS,RATIO (repeat for more; "
                   "they may not overlap): its centre at X,Y mm on the footprint (from the "
                   "block's corner at P00's side: 0..L along +x, 0..W along +y) and DEPTH mm "
                   "below the rest surface (the depth of its centre: 0..{:g}), RADIUS mm ({:g} "
                   "to {:g}; the block's faces cut a sphere that reaches past them), RATIO its "
                   "stiffness over the block's ({:g} to {:g}). E.g. 50,50,10,12,3.".format(
                       THICKNESS_MM, RADIUS_RANGE_M[0] * 1e3, RADIUS_RANGE_M[1] * 1e3,
                       *RATIO_RANGE))
@click.option("--layer", type=LAYER, default=D.layer,
              help="A top layer of another silicone, THICKNESS,RATIO: from the rest surface "
                   "down THICKNESS mm (less than the block's {:g}), RATIO its stiffness over "
                   "the block's ({:g} to {:g}; an inclusion in it keeps its own). E.g. 3,2 (a "
                   "stiff skin).".format(THICKNESS_MM, *RATIO_RANGE))
@click.option("--shape", default=D.shape,
              help="A curved phantom: dome:HEIGHT (a spherical cap HEIGHT mm high, 1 to 60, "
                   "over the block, meeting it at the footprint's corners) or an STL/OBJ/PLY "
                   "surface in mm whose base stands flat on the table (its footprint replaces "
                   "--size). Writes mould.stl and [phantom] shape; presses go along the local "
                   "normal. No --inclusion or --layer with it.")
@click.option("--mocap-rate", "rate_hz", type=MOCAP_RATE, default=D.rate_hz, show_default=True,
              help="Mocap frame rate in Hz (the force logger stays at 1 kHz; --force-via "
                   "analog or plate needs a rate that divides 1000).")
@click.option("--view-press", type=ranged(B["view_press"]), default=D.view_press,
              show_default=True,
              help="Press shown in the rerun recording.")
@seed_option(D.seed)
@rrd_option
def synth(out_dir: Path, locations: int | str, repeats: int, press_seconds: float | None,
          pivot_seconds: float, trigger: bool, offset_s: float | None, drift_ppm: float | None,
          force_via: str, force_file: str | None, markers: str, marker_pitch_mm: float,
          size: str, inclusions: tuple[str, ...], layer: str | None, shape: str | None,
          rate_hz: float,
          view_press: int, seed: int, rrd: Path | None, no_rrd: bool) -> None:
    """Simulate a phantom indentation session and write it as the lab would.

    Reads nothing. Writes OUT_DIR: session.toml (with the [phantom] table: the footprint, and how
    the markers fix the phantom frame); indentation.tsv and indentation_6D.tsv (QTM TSV 3D of
    the phantom markers, --markers, + 4 indenter markers and 6D of the body 'Indenter', at
    --mocap-rate, noise and gaps); pivot.tsv (QTM TSV 3D, the tip in a divot); force.csv and
    force.mat (Speedgoat log at 1 kHz on its own clock: six Nano17 gauge voltages with bias,
    and the trigger), or with --force-via analog the same gauges at 1 kHz on the mocap clock in
    indentation.c3d (with the markers) and indentation_a.tsv (QTM analog export), or with
    --force-via plate a force plate under the phantom at 1 kHz on the mocap clock in
    indentation_f_1.tsv (QTM force-plate export: force N, moment N m, centre of pressure mm);
    FT<serial>.cal (ATI calibration, SI-12-0.12; none with a plate); truth.h5 (noise-free
    markers and tip on the mocap clock, true force, clock offset and drift, tip offset, static
    states every 0.5 N, the inclusions and the layer); and a rerun recording of one press
    beside its truth (--rrd, default OUT_DIR/recording.rrd). OUT_DIR is new, empty, or an
    earlier synth session: then the files of that session this run does not rewrite (another
    FT<serial>.cal, a recording.rrd) are removed, and files the twin does not write are left
    alone. The same seed gives the same bytes of data. `pipeline ingest OUT_DIR` reads the
    folder as it is.
    """
    from sim.twin.synth_stage import run_synth

    rrd_path = resolve_rrd(out_dir, rrd, no_rrd)
    start = time.perf_counter()
    params = SynthParams(
        seed=seed, locations=locations, repeats=repeats, press_seconds=press_seconds,
        pivot_seconds=pivot_seconds, trigger=trigger, offset_s=offset_s, drift_ppm=drift_ppm,
        force_via=force_via, force_file=force_file, rate_hz=rate_hz, markers=markers,
        marker_pitch_mm=marker_pitch_mm, size=size, inclusions=inclusions, layer=layer,
        shape=shape, view_press=view_press)
    folder = run_synth(None, out_dir, params, rrd_path)
    grid = "" if isinstance(locations, int) else f" (a {locations} grid)"
    found, top = params.regions()
    regions = "".join(f", inclusion {i.describe()}" for i in found) + (
        f", layer {top.describe()}" if top else "")
    click.echo(f"{folder}: {params.places * repeats} presses at {params.places} locations"
               f"{grid}, {markers} markers on {size} mm{regions}"
               f"{f', shape {shape}' if shape else ''} at {rate_hz:g} Hz, seed {seed}, "
               f"in {time.perf_counter() - start:.1f} s"
               + (f"; recording {rrd_path}" if rrd_path else ""))

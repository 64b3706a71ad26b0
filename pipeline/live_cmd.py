"""``pipeline live``: the click layer over :func:`live.session.live_stage.run_live`."""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from core.text import count
from live.protocol.address import parse_address
from live.session.live_params import LiveParams
from pipeline.options import Checkpoint, Parsed, ranged

D = LiveParams              # the option defaults are its fields', the bounds its BOUNDS


@click.command()
@click.argument("session_dir", type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option("--qtm", "address", type=Parsed("HOST[:PORT]", parse_address),
              default=(D.host, D.port),
              help="QTM's real-time server (its little-endian port; 22223 unless said) "
                   f"[default: {D.host}:{D.port}].")
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="A new folder: session.mcap (the session as `pipeline ingest` writes it), "
                   "session.rrd (the live recording) and states.h5 (the states taken live).")
@click.option("--duration", "duration_s", type=ranged(D.BOUNDS["duration_s"]),
              default=D.duration_s, help="Stop after this many seconds [default: until QTM stops, "
                                 "Ctrl-C, or the connection ends].")
@click.option("--timeout", "timeout_s",
              type=ranged(D.BOUNDS["timeout_s"]),
              default=D.timeout_s, show_default=True,
              help="Seconds to wait for QTM to answer, and for the next frame.")
@click.option("--calibration", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              default=None, help="A synced file (`pipeline sync`) whose tip calibration to "
                                 "use instead of the session's pivot recording.")
@click.option("--model", type=Checkpoint(folder=True), default=None,
              help="A trained run (`pipeline train`; its folder or a checkpoint) trained on "
                   "this phantom's markers, or 'generic' (the generic model shipped with the "
                   "package: a first session's prediction before any training): its surface "
                   "for the tip now beside the markers, its L_d and force error, as each "
                   "press goes on.")
@click.option("--spawn", is_flag=True, help="Also show the recording in a rerun viewer.")
@click.option("--serve", is_flag=True, help="Also serve the recording to a web browser.")
@click.option("--states/--no-states", default=D.states, show_default=True,
              help="Write the static states taken press by press as the session goes on "
                   "(sync's and extract's rules) to --out/states.h5 at the end.")
@click.option("--recover", is_flag=True,
              help="Connect to nothing: finish the journal a killed session left in --out "
                   "(session.mcap.part, every complete block) as --out/session.mcap.")
@click.option("--reconnect", "reconnect_s", type=ranged(D.BOUNDS["reconnect_s"]),
              default=D.reconnect_s, show_default=True,
              help="After a lost connection, keep trying to reconnect this long and go on "
                   "into the same session.mcap (frames the server sends again are recorded "
                   "once); 0: a lost connection ends the session.")
@click.option("--no-rrd", is_flag=True, help="Write no recording.")
def live(session_dir: Path, address: tuple[str, int], out: Path, duration_s: float | None,
         timeout_s: float, calibration: Path | None, model: Path | None, spawn: bool,
         serve: bool, states: bool, recover: bool, reconnect_s: float, no_rrd: bool) -> None:
    """Record a session live from QTM's real-time stream, and show it as it happens.

    Reads SESSION_DIR's session.toml (the markers, the force's channels, kind and units, the
    ATI .cal, the pivot recording) and QTM's parameters, and refuses in one line what does not
    agree (a marker QTM lacks, a force plate or analog channel it lacks, units or a rate that
    contradict session.toml) before a frame is read. Then streams 3D markers and the force
    (QTM's force component of the plate where session.toml's force file is a QTM force-plate
    export, else the force's analog board) until --duration, Ctrl-C, QTM's end of the
    recording or a lost connection. Writes --out/session.mcap as
    `pipeline ingest` would (every frame received, each stream on its clock; `pipeline sync`
    runs on it), built from a journal written as the frames arrive (session.mcap.part: what a
    kill leaves), and --out/session.rrd: markers, tip, the tared force at the mocap rate, lost
    markers, saturation and over-range as they happen, each press as it ends and the coverage
    of the locations pressed (presses, states, highest level read). Each press's static states
    are taken 1.5 s after it ends, with sync's and extract's rules; with --states (the default)
    they are written at the end to --out/states.h5 (what `pipeline sync` and `pipeline extract`
    give on session.mcap).
    """
    from live.session.live_stage import MCAP_NAME, RRD_NAME, run_live

    host, port = address
    params = LiveParams(host=host, port=port, duration_s=duration_s, timeout_s=timeout_s,
                        calibration=calibration, model=model, spawn=spawn, serve=serve,
                        states=states, recover=recover, reconnect_s=reconnect_s)
    s = run_live(session_dir, out, params, None if no_rrd or recover else out / RRD_NAME)
    lat = s.latency_ms
    timing = f"; per frame {np.median(lat):.2f} ms median, {np.percentile(lat, 99):.2f} ms " \
             "p99" if lat.size else ""
    resent = f", {s.counts.resent} sent again after reconnecting" if s.counts.resent else ""
    click.echo(f"{out / MCAP_NAME}: {s.counts.frames} frames ({s.counts.skipped} skipped by "
               f"number{resent}), {s.counts.samples} force samples from {s.source} in "
               f"{s.seconds:.1f} s; ended: {s.ended}; {s.presses} presses at "
               f"{len(s.locations)} locations{timing}" + (f"; {s.states}" if s.states else "")
               + (f"; the model refused {count(s.model_refused, 'press')}" if s.model_refused
                  else "") + (f"; recording {s.rrd}" if s.rrd else ""))

"""``pipeline replay``: the click layer over :func:`live.replay.replay_stage.run_replay`."""

from __future__ import annotations

from pathlib import Path

import click

from core.text import count
from live.replay.replay_params import ReplayParams
from pipeline.options import ranged

D = ReplayParams              # the option defaults are its fields', the bounds its BOUNDS


@click.command()
@click.argument("session", type=click.Path(path_type=Path))
@click.option("--port", type=ranged(D.BOUNDS["port"]), default=D.port, show_default=True,
              help="TCP port to serve on (QTM's little-endian port; 0: any free one, shown).")
@click.option("--host", default=D.host, show_default=True,
              help="Address to listen on (0.0.0.0: every interface).")
@click.option("--speed", type=ranged(D.BOUNDS["speed"]),
              default=D.speed, show_default=True,
              help="Times real time: 1 plays the frames at their recorded rate, 50 fifty "
                   "times faster.")
@click.option("--max-clients", type=ranged(D.BOUNDS["max_clients"]), default=D.max_clients,
              show_default=True,
              help="Stop once this many clients have come and gone (0: serve until Ctrl-C).")
def replay(session: Path, port: int, host: str, speed: float, max_clients: int) -> None:
    """Serve a recorded session as QTM's real-time server would, for live work without a QTM.

    Reads SESSION: a session folder (its session.toml and lab files, read as `pipeline
    ingest` reads them; a twin's from `pipeline synth`) or an MCAP from `pipeline ingest`.
    Writes nothing: it serves the session over the QTM RT protocol (TCP, little-endian) on
    --host:--port. A client negotiates the version (1.11 to 1.28), asks `GetParameters
    General 3D Analog Force` (QTM's XML: the marker rate, the labels of the phantom and
    indenter markers, the force as one analog device) and streams `StreamFrames AllFrames 3D
    3DNoLabels Analog Force` (or every n-th frame): markers in mm, NaN when lost, and the
    force's samples, paced at --speed times the recorded rate, every frame sent. Each client
    plays the recording from its start; at its end the server sends QTM's event "RT from file
    stopped". Force logged on its own clock (not through the mocap's analog board: `pipeline
    synth --force-via analog` makes a session whose force is) is apportioned to the frames by
    its own time read as the mocap's, so the client sees one clock; samples outside the
    frames are left out and counted. Ctrl-C stops; one line then says what was served.
    """
    from live.replay.replay_stage import run_replay

    params = ReplayParams(port=port, host=host, speed=speed, max_clients=max_clients)
    s = run_replay(session, None, params, None)
    left = f"; {s.samples_left_out:,} force samples outside the frames left out" if \
        s.samples_left_out else ""
    click.echo(f"{session}: {s.frames_sent:,} frames sent to {count(s.clients, 'client')} in "
               f"{s.seconds:.1f} s{left}")

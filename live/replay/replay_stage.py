"""The replay runner: a session folder or an ingested MCAP served over the QTM real-time
protocol (:mod:`live.replay.server`) until Ctrl-C, or until ``max_clients`` clients have come
and gone. It writes nothing."""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass
from pathlib import Path

from live.replay.replay_params import ReplayParams
from live.replay.server import ReplayServer
from live.replay.source import read_replay_source


@dataclass(frozen=True)
class ReplaySummary:
    """What a replay did: the session, the clients served, the frames sent, how long it ran,
    and the force samples no frame could carry (a log on its own clock)."""

    name: str
    clients: int
    frames_sent: int
    seconds: float
    samples_left_out: int


def run_replay(inputs: str | Path, out: None, params: ReplayParams | None = None,
               rrd: None = None) -> ReplaySummary:
    """Serve the session folder or MCAP ``inputs``; ``out`` and ``rrd`` are None (nothing is
    written). Returns when stopped (Ctrl-C) or after ``params.max_clients`` clients."""
    params = params or ReplayParams()
    if out is not None or rrd is not None:
        raise ValueError("the replay writes nothing: out and rrd must be None")
    source = read_replay_source(inputs)
    server = ReplayServer(source, params)
    start = time.monotonic()
    try:
        asyncio.run(server.serve())
    except KeyboardInterrupt:
        pass                                     # Ctrl-C: the normal end of a replay
    return ReplaySummary(source.name, server.stats.clients, server.stats.frames_sent,
                         time.monotonic() - start, source.force.left_out)

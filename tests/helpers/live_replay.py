"""The replay server in a thread of its own, for tests that run ``pipeline live`` against it
(run_live runs its own event loop)."""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Iterator
from pathlib import Path

from live.replay_params import ReplayParams
from live.replay_server import ReplayServer
from live.replay_source import read_replay_source

SPEED = 20.0                  # times real time: a 20 s twin session in about a second


@contextlib.contextmanager
def replaying(session: Path, speed: float = SPEED) -> Iterator[ReplayServer]:
    """The replay server of ``session`` on a free port, in a thread of its own."""
    loop = asyncio.new_event_loop()
    server = ReplayServer(read_replay_source(session), ReplayParams(port=0, speed=speed))
    loop.run_until_complete(server.start())
    thread = threading.Thread(target=loop.run_forever, daemon=True)
    thread.start()
    try:
        yield server
    finally:
        asyncio.run_coroutine_threadsafe(server.close(), loop).result(10)
        loop.call_soon_threadsafe(loop.stop)
        thread.join(10)


STATE_KEYS = ("states/step", "states/sequence", "states/location", "single/start",
              "single/end", "multi/start", "multi/end")


def offline_states(mcap: Path, folder: Path) -> Path:
    """``pipeline sync`` + ``pipeline extract`` of an ingested ``mcap`` into ``folder``: the
    states file the live session's must equal."""
    from extract.extract_params import ExtractParams
    from extract.extract_stage import run_extract
    from sync.sync_params import SyncParams
    from sync.sync_stage import run_sync

    folder.mkdir(parents=True, exist_ok=True)
    run_sync(mcap, folder / "s.h5", SyncParams(), None)
    run_extract([folder / "s.h5"], folder / "states.h5", ExtractParams(), None)
    return folder / "states.h5"


def assert_same_states(live: Path, offline: Path, keys: tuple[str, ...] = STATE_KEYS) -> None:
    """The states taken live are the offline stages': the same presses, levels, sequences,
    locations and examples, points within 0.05 mm, forces within 1 mN."""
    import numpy as np

    from data_schema.hdf5 import read_h5
    from data_schema.states import STATES

    got, _ = read_h5(live, STATES)
    want, _ = read_h5(offline, STATES)
    for key in keys:
        np.testing.assert_array_equal(got[key], want[key], err_msg=key)
    np.testing.assert_allclose(got["states/points"], want["states/points"], atol=5e-5)
    np.testing.assert_allclose(got["states/force"], want["states/force"], atol=1e-3)

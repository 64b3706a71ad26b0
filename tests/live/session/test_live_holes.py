"""A live session that lost frames: QTM has one timeline for every client, so a client that
comes back after a dropped connection gets the frames due now, and those of the gap are gone.
The session goes on; its MCAP is a session with a hole that ``pipeline sync`` reads again;
the states taken live are the offline chain's on that MCAP, and the presses the gap touched
are the only ones left out of them."""

from __future__ import annotations

import asyncio
import contextlib
from pathlib import Path

import h5py
import numpy as np
import pytest
from helpers.live_replay import (
    assert_same_states,
    offline_states,
    replaying,
    threaded_server,
)

from ingest.ingest_params import IngestParams
from ingest.ingest_stage import run_ingest
from ingest.mcap_io import read_raw_mcap
from live.protocol.packets import PacketReader, PacketType, decode_data
from live.session.live_params import LiveParams
from live.session.live_stage import MCAP_NAME, STATES_NAME, run_live

GAP = (6000, 6600)           # frames [first lost, first received again): 1.2 s at 500 Hz


class OneTimeline:
    """A proxy in front of the replay that plays QTM's one timeline: its first connection is
    hung up at frame ``gap[0]``; a client that comes back is sent the frames from
    ``gap[1]`` on (those before it were due while it was away)."""

    def __init__(self, upstream: int, gap: tuple[int, int]) -> None:
        self.upstream, self.gap, self.connections = upstream, gap, 0
        self.loop, self.server, self.port, self.thread = threaded_server(self._client)

    def close(self) -> None:
        self.loop.call_soon_threadsafe(self.server.close)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.connections += 1
        first = self.connections == 1
        up_reader, up_writer = await asyncio.open_connection("127.0.0.1", self.upstream)
        ask = asyncio.ensure_future(self._forward(reader, up_writer))
        packets = PacketReader()
        with contextlib.suppress(ConnectionError):
            while data := await up_reader.read(65536):
                out = bytearray()
                for p in packets.feed(data):
                    frame = decode_data(p.payload).frame if p.type == PacketType.DATA else None
                    if first and frame is not None and frame >= self.gap[0]:
                        writer.write(bytes(out))
                        writer.close()                 # the connection drops here
                        up_writer.close()
                        ask.cancel()
                        return
                    if not first and frame is not None and frame < self.gap[1]:
                        continue                       # due while the client was away
                    out += (8 + len(p.payload)).to_bytes(4, "little") + \
                        int(p.type).to_bytes(4, "little") + p.payload
                writer.write(bytes(out))
                await writer.drain()
        writer.close()
        ask.cancel()

    @staticmethod
    async def _forward(src: asyncio.StreamReader, dst: asyncio.StreamWriter) -> None:
        with contextlib.suppress(ConnectionError):
            while data := await src.read(65536):
                dst.write(data)
                await dst.drain()


@pytest.fixture(scope="module")
def dropped(twin_session: Path, tmp_path_factory: pytest.TempPathFactory):
    """The twin session recorded live through a connection dropped at frame 6000 and
    reconnected (``--reconnect``) onto QTM's one timeline, and the same session ingested."""
    out = tmp_path_factory.mktemp("dropped") / "live"
    with replaying(twin_session) as server:
        proxy = OneTimeline(server.port, GAP)
        try:
            summary = run_live(twin_session, out, LiveParams(port=proxy.port, timeout_s=10,
                                                             reconnect_s=10), None)
        finally:
            proxy.close()
    whole = out.parent / "whole.mcap"
    run_ingest(twin_session, whole, IngestParams(), None)
    return summary, out, whole


def test_the_session_goes_on_past_the_gap(dropped) -> None:
    """Every frame but the gap's is recorded once; the MCAP keeps the jump in its clocks."""
    summary, out, whole = dropped
    live, full = read_raw_mcap(out / MCAP_NAME), read_raw_mcap(whole)
    lost = GAP[1] - GAP[0]
    assert summary.counts.skipped == lost
    assert live.markers.frames == full.markers.frames - lost
    keep = np.r_[np.arange(GAP[0] - 1), np.arange(GAP[1] - 1, full.markers.frames)]
    np.testing.assert_array_equal(live.markers.time_ns, full.markers.time_ns[keep])
    np.testing.assert_allclose(live.markers.positions, full.markers.positions[keep],
                               atol=1e-7, equal_nan=True)


def test_sync_reads_the_live_mcap_again_and_finds_the_live_states(dropped, tmp_path) -> None:
    """`pipeline sync` + `extract` on the MCAP live wrote give the states live took: the
    same presses and levels, points within 0.05 mm."""
    _, out, _ = dropped
    assert_same_states(out / STATES_NAME, offline_states(out / MCAP_NAME, tmp_path / "again"))


def test_only_the_presses_the_gap_touched_are_left_out(dropped, tmp_path) -> None:
    """Against the same session without the gap: each press away from it keeps its levels and
    points (0.05 mm); the one the gap falls in is gone, and said."""
    summary, out, whole = dropped
    full = offline_states(whole, tmp_path / "whole")
    with h5py.File(out / STATES_NAME) as a, h5py.File(full) as b:
        got = {int(s): a["states/points"][a["states/sequence"][()] == s]
               for s in np.unique(a["states/sequence"][()])}
        want = {int(s): b["states/points"][b["states/sequence"][()] == s]
                for s in np.unique(b["states/sequence"][()])}
        t_gap = read_raw_mcap(whole).markers.time_ns[list(GAP)] * 1e-9
    assert len(got) == len(want) - 1
    assert "press" in summary.states and "left out: a hole" in summary.states
    tips = {k: v[0, -1] for k, v in want.items()}
    for points in got.values():
        k = min(tips, key=lambda j: np.linalg.norm(tips[j] - points[0, -1]))
        assert len(want[k]) == len(points)
        assert np.nanmax(np.linalg.norm(points - want[k], axis=2)) < 0.05e-3
    assert t_gap[1] - t_gap[0] == pytest.approx(1.2)

"""QTM servers in a thread of their own, for tests that run ``pipeline live`` against them
(run_live runs its own event loop): the replay, and a scripted QTM that fails at each step of
the protocol's dialogue; what the live session's states must equal; the process's sockets."""

from __future__ import annotations

import asyncio
import contextlib
import os
import threading
from collections.abc import Iterator
from pathlib import Path

from live.protocol.commands import GREETING
from live.protocol.packets import (
    AnalogBlock,
    Component,
    Event,
    PacketReader,
    encode_3d,
    encode_analog,
    encode_command,
    encode_data,
    encode_error,
    encode_event,
    encode_no_more_data,
    encode_xml,
    text_of,
)
from live.replay.frames import frame_packet
from live.replay.parameters import DEVICE_ID, parameters_xml
from live.replay.replay_params import ReplayParams
from live.replay.server import ReplayServer
from live.replay.source import read_replay_source

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


# -- a QTM that fails, step by step ------------------------------------------------------------

# where a scripted QTM fails on one connection (the steps of the dialogue, in order)
FAULTS = ("greeting refused", "version refused", "version silent", "parameters refused",
          "parameters not xml", "stream refused", "stream no more data", "stream silent",
          "damaged packet", "impossible size", "wrong marker count", "dropped",
          "another capture", "marker missing", "none")
CLIENT_CLOSE_S = 20.0         # the longest a client may take to close its side



def threaded_server(handler) -> tuple[asyncio.AbstractEventLoop, asyncio.Server, int,
                                      threading.Thread]:
    """A TCP server on a free local port whose event loop runs in a daemon thread: (its loop,
    the server, the port, the thread)."""
    loop = asyncio.new_event_loop()
    server = loop.run_until_complete(asyncio.start_server(handler, "127.0.0.1", 0))
    thread = threading.Thread(target=loop.run_forever, daemon=True)
    thread.start()
    return loop, server, server.sockets[0].getsockname()[1], thread

class FaultyQtm:
    """A QTM real-time server (on a free port, in a thread of its own) that follows one fault
    of :data:`FAULTS` per connection, in order (``faults``); once the last is taken, it
    listens no more (a reconnection is refused). ``frames``: the frames of ``source`` it
    streams before a mid-stream fault. After its script, a connection waits for the client
    to close its side (it says nothing more, and hangs up only where its fault is
    "dropped"): :attr:`closed_by_client` counts those the client closed, of :attr:`accepted`."""

    def __init__(self, session: Path, faults: list[str], frames: int = 300) -> None:
        assert all(f in FAULTS for f in faults), faults
        self.source, self.faults, self.frames = read_replay_source(session), faults, frames
        self.accepted = self.closed_by_client = 0
        self._handlers: list[asyncio.Task] = []
        self._loop, self._server, self.port, self._thread = threaded_server(self._client)

    def close(self) -> None:
        """Wait for every connection's handler (the client closing its side), then stop."""
        async def finish() -> None:
            self._server.close()
            if self._handlers:
                await asyncio.wait(self._handlers, timeout=CLIENT_CLOSE_S + 5)
            await self._server.wait_closed()

        asyncio.run_coroutine_threadsafe(finish(), self._loop).result(CLIENT_CLOSE_S + 10)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(10)
        self._loop.close()

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self._handlers.append(asyncio.current_task())
        fault = self.faults[self.accepted]
        self.accepted += 1
        if self.accepted == len(self.faults):
            self._server.close()                      # no more connections
        try:
            await self._play(fault, _Commands(reader), writer)
            if fault == "dropped":
                writer.write_eof()                    # hang up our side; read on
            await writer.drain()
            await asyncio.wait_for(_until_eof(reader), CLIENT_CLOSE_S)
            self.closed_by_client += 1
        except (TimeoutError, ConnectionError):
            pass
        finally:
            writer.close()

    async def _play(self, fault: str, commands: _Commands, writer: asyncio.StreamWriter
                    ) -> None:
        """The dialogue up to ``fault``, and the fault."""
        if fault == "greeting refused":
            writer.write(encode_error("Connection refused: too many clients"))
            return
        writer.write(encode_command(GREETING))
        await commands.next()                                    # Version 1.25
        if fault == "version silent":
            return
        if fault == "version refused":
            writer.write(encode_error("Version 1.25 NOT supported"))
            return
        writer.write(encode_command("Version set to 1.25"))
        await commands.next()                                    # GetParameters ...
        if fault == "parameters refused":
            writer.write(encode_error("GetParameters: no measurement"))
            return
        writer.write(encode_xml(self._parameters(fault)))
        if fault in ("parameters not xml", "another capture", "marker missing"):
            return
        await commands.next()                                    # StreamFrames ...
        if fault == "stream refused":
            writer.write(encode_error("StreamFrames: no measurement running"))
        elif fault == "stream no more data":
            writer.write(encode_no_more_data())
        elif fault != "stream silent":
            self._stream(fault, writer)

    def _parameters(self, fault: str) -> str:
        xml = parameters_xml(self.source, ("general", "3d", "analog", "force"), "1.25")
        first = self.source.labels[0]
        if fault == "parameters not xml":
            return xml[:len(xml) // 2]
        if fault == "another capture":                           # one more marker
            return xml.replace("</The_3D>", "<Label><Name>stray</Name></Label></The_3D>")
        if fault == "marker missing":                            # a session's marker renamed
            return xml.replace(f"<Name>{first}</Name>", f"<Name>{first}x</Name>")
        return xml

    def _stream(self, fault: str, writer: asyncio.StreamWriter) -> None:
        """``frames`` frames, then the fault (or, for "none", the end event)."""
        components = [Component.THREE_D, Component.ANALOG]
        for i in range(self.frames):
            writer.write(frame_packet(self.source, i, components))
        nxt = frame_packet(self.source, self.frames, components)
        if fault == "damaged packet":          # its first component claims more than is sent
            size = int.from_bytes(nxt[24:28], "little")
            writer.write(nxt[:24] + (size + 1000).to_bytes(4, "little") + nxt[28:])
        elif fault == "impossible size":       # a header of size 0: no packet at all
            writer.write(bytes(8) + nxt)
        elif fault == "dropped":
            writer.write(nxt[:len(nxt) // 2])
        elif fault == "wrong marker count":    # a frame of one marker fewer than its labels
            source, frame = self.source, self.frames
            writer.write(encode_data(source.timestamp_us(frame), frame + 1, [
                encode_3d(source.markers_mm[frame][1:]),
                encode_analog([AnalogBlock(DEVICE_ID, *source.force.samples(frame, frame + 1))])]))
        else:
            writer.write(encode_event(Event.RT_FROM_FILE_STOPPED))


class _Commands:
    """The commands a client sends, one at a time."""

    def __init__(self, reader: asyncio.StreamReader) -> None:
        self.reader, self.packets, self.queue = reader, PacketReader(), []

    async def next(self) -> str:
        while not self.queue:
            data = await self.reader.read(1 << 16)
            if not data:
                raise ConnectionError("the client left")
            self.queue += self.packets.feed(data)
        return text_of(self.queue.pop(0).payload)


async def _until_eof(reader: asyncio.StreamReader) -> None:
    while await reader.read(1 << 16):
        pass


def open_sockets() -> int | None:
    """This process's open sockets (Linux: /proc/self/fd), None where that cannot be read."""
    fds = Path("/proc/self/fd")
    if not fds.is_dir():
        return None
    count = 0
    for fd in fds.iterdir():
        with contextlib.suppress(OSError):
            count += os.readlink(fd).startswith("socket:")
    return count

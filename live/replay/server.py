"""An asyncio TCP server that replays a session over the QTM real-time protocol.

A client is greeted with "QTM RT Interface connected", may negotiate the protocol version
(1.11 to 1.28; 1.25 until it does), ask for the parameters (:mod:`live.replay.parameters`)
and stream frames (:mod:`live.replay.frames`). Each client has its own playback of the recording,
from its first frame: ``StreamFrames`` plays on from where the client's playback stands,
``StreamFrames Stop`` pauses it, and after the last frame the server sends the event "RT from
file stopped" (QTM's end of a file played in real time) and keeps the connection until the
client leaves; a ``StreamFrames`` after that gets "no more data". Frames go out at their
recorded times, times ``speed``, measured on the wall clock from the stream's start, so no
drift accumulates; a client that reads slowly gets every frame late, never fewer frames
(TCP's flow control holds the server back). Clients are served side by side and one after
another; one that leaves mid-stream ends its stream, no other.

Like QTM, the server sends no reply to ``StreamFrames``: the first data packet is the answer.
"""

from __future__ import annotations

import asyncio
import os
import socket
from dataclasses import dataclass

from core.errors import BadInput
from core.progress import say
from live.protocol.commands import (
    GREETING,
    Command,
    GetCurrentFrame,
    GetParameters,
    Plain,
    Refused,
    StopStreaming,
    StreamFrames,
    Version,
    parse_command,
)
from live.protocol.packets import (
    Event,
    Packet,
    PacketReader,
    PacketType,
    ProtocolError,
    encode_command,
    encode_error,
    encode_event,
    encode_no_more_data,
    encode_xml,
    text_of,
)
from live.replay.frames import frame_packet
from live.replay.parameters import parameters_xml
from live.replay.replay_params import ReplayParams
from live.replay.source import ReplaySource

DEFAULT_VERSION = "1.25"
MINOR_VERSIONS = range(11, 29)    # 1.11 to 1.28: these components' layouts, the analog XML's
YIELD_EVERY = 32                  # frames sent back to back before other clients get a turn
READ_BYTES = 1 << 16


@dataclass
class ReplayStats:
    """What the server has done so far: clients connected and left, frames sent."""

    clients: int = 0
    left: int = 0
    frames_sent: int = 0


class ReplayServer:
    """Serves ``source`` on ``params.host``:``params.port`` until :meth:`stop` or until
    ``params.max_clients`` clients have come and gone (0: until stopped)."""

    def __init__(self, source: ReplaySource, params: ReplayParams) -> None:
        self.source, self.params = source, params
        self.stats = ReplayStats()
        self.port: int | None = None
        self._server: asyncio.Server | None = None
        self._done: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._clients: dict[asyncio.Task, asyncio.StreamWriter] = {}

    async def serve(self) -> None:
        """Listen, serve until stopped, then close every connection."""
        await self.start()
        try:
            await self._stopping().wait()
        finally:
            await self.close()

    async def start(self) -> int:
        """Listen; returns the port (the one chosen where ``params.port`` is 0). A port in
        use or an unknown host is bad input naming it."""
        p = self.params
        self._loop, self._done = asyncio.get_running_loop(), asyncio.Event()
        try:
            self._server = await asyncio.start_server(self._client, p.host, p.port)
        except OSError as e:
            # asyncio words a bind error at length; a lookup error's own words are short
            code = None if isinstance(e, socket.gaierror) else e.errno
            why = os.strerror(code) if code else (e.strerror or str(e))
            raise BadInput(f"{p.host}:{p.port}", f"cannot listen there ({why})") from None
        self.port = self._server.sockets[0].getsockname()[1]
        s = self.source
        say(f"replay: {s.name}, {s.frames:,} frames at {s.rate_hz:g} Hz, {len(s.labels)} "
            f"markers, the force as {s.force.describe()} at {s.force.rate_hz:g} Hz; "
            f"serving QTM RT on {p.host}:{self.port} at {p.speed:g}x real time")
        return self.port

    def stop(self) -> None:
        """End :meth:`serve` (from any thread)."""
        if self._loop is not None:
            self._loop.call_soon_threadsafe(self._stopping().set)

    def _stopping(self) -> asyncio.Event:
        """What ends :meth:`serve`, made when the server starts."""
        if self._done is None:
            raise RuntimeError("the replay server is not started")
        return self._done

    async def close(self) -> None:
        """Stop listening and end every connection (its handler then ends as on a client's
        leaving)."""
        if self._server is not None:
            self._server.close()
        for writer in self._clients.values():
            writer.transport.abort()
        if self._clients:
            await asyncio.wait(list(self._clients))
        if self._server is not None:
            await self._server.wait_closed()

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        """One client's connection, from the greeting until it leaves."""
        task = asyncio.current_task()
        if task is None:                    # asyncio runs each connection's handler as a task
            raise RuntimeError("a client's connection handled outside a task")
        self._clients[task] = writer
        self.stats.clients += 1
        client = _Client(self.source, self.params.speed, writer, self.stats)
        try:
            writer.write(encode_command(GREETING))
            packets = PacketReader()
            while data := await reader.read(READ_BYTES):
                for packet in packets.feed(data):
                    if not await client.handle(packet):
                        return
        except (ConnectionError, ProtocolError):
            pass                                    # it left, or spoke no QTM RT: dropped
        finally:
            await client.stop_stream()
            writer.close()
            del self._clients[task]
            self.stats.left += 1
            if self.params.max_clients and self.stats.left >= self.params.max_clients:
                self._stopping().set()


class _Client:
    """The dialogue with one client: its protocol version, its playback and its stream."""

    def __init__(self, source: ReplaySource, speed: float, writer: asyncio.StreamWriter,
                 stats: ReplayStats) -> None:
        self.source, self.speed, self.writer, self.stats = source, speed, writer, stats
        self.version = DEFAULT_VERSION
        self.next = 0                               # the playback: the next frame to play
        self.stream: asyncio.Task | None = None

    async def handle(self, packet: Packet) -> bool:
        """Answer one packet; False when the client says goodbye."""
        if packet.type != PacketType.COMMAND:
            self._send(encode_error("Parse error: the replay takes commands only"))
            return True
        try:
            command = parse_command(text_of(packet.payload))
        except Refused as e:
            self._send(encode_error(str(e)))
            return True
        return await self._do(command)

    async def _do(self, command: Command) -> bool:
        match command:
            case Version(number=None):
                self._send(encode_command(f"Version is {self.version}"))
            case Version(number=str() as number):
                self._set_version(number)
            case GetParameters(sections=sections):
                self._send(encode_xml(parameters_xml(self.source, sections, self.version)))
            case StreamFrames():
                await self._start_stream(command)
            case StopStreaming():
                await self.stop_stream()
            case GetCurrentFrame(components=components):
                self._send(frame_packet(self.source, max(self.next - 1, 0), components))
            case Plain(name="byebye"):
                return False
            case Plain(name="getstate"):
                over = self.next >= self.source.frames
                self._send(encode_event(Event.RT_FROM_FILE_STOPPED if over
                                        else Event.RT_FROM_FILE_STARTED))
            case Plain(name="byteorder"):
                self._send(encode_command("Byte order is little endian"))
            case Plain(name="qtmversion"):
                self._send(encode_command("QTM Version is phantom-pipeline replay"))
        return True

    def _set_version(self, number: str) -> None:
        major, _, minor = number.partition(".")
        if major != "1" or not minor.isdigit() or int(minor) not in MINOR_VERSIONS:
            self._send(encode_error(f"Version {number} NOT supported"))
            return
        self.version = f"1.{int(minor)}"
        self._send(encode_command(f"Version set to {self.version}"))

    async def _start_stream(self, request: StreamFrames) -> None:
        await self.stop_stream()
        if self.next >= self.source.frames:
            self._send(encode_no_more_data())       # played to the end already
            return
        self.stream = asyncio.create_task(self._play(request))

    async def stop_stream(self) -> None:
        """End the stream, if one runs, between two frames."""
        if self.stream is not None and not self.stream.done():
            self.stream.cancel()
            await asyncio.wait([self.stream])
        self.stream = None

    async def _play(self, request: StreamFrames) -> None:
        """Send the frames from the playback's position on, each at its time, then the end
        event; a client gone mid-stream ends it."""
        src, loop = self.source, asyncio.get_running_loop()
        first, step = self.next, request.step(src.rate_hz)
        t0, base = loop.time(), int(src.time_ns[first])
        try:
            for n, frame in enumerate(range(first, src.frames, step)):
                await _pace(loop, t0 + (int(src.time_ns[frame]) - base) * 1e-9 / self.speed, n)
                if self.writer.is_closing():
                    return
                self.writer.write(frame_packet(src, frame, request.components, self.next))
                self.next = frame + 1
                self.stats.frames_sent += 1
                await self.writer.drain()
            self.next = src.frames
            self._send(encode_event(Event.RT_FROM_FILE_STOPPED))
        except ConnectionError:
            return

    def _send(self, packet: bytes) -> None:
        if not self.writer.is_closing():
            self.writer.write(packet)


async def _pace(loop: asyncio.AbstractEventLoop, due: float, n: int) -> None:
    """Wait for the wall-clock time ``due``; behind time, yield every :data:`YIELD_EVERY`
    frames so that commands and other clients are heard."""
    delay = due - loop.time()
    if delay > 0:
        await asyncio.sleep(delay)
    elif n % YIELD_EVERY == 0:
        await asyncio.sleep(0)

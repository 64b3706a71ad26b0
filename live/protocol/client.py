"""The QTM real-time client ``pipeline live`` connects with: a TCP connection that speaks the
protocol through :mod:`live.protocol.packets` and :mod:`live.protocol.commands`, and decodes
each frame into numpy arrays.

:func:`connect` reads the server's greeting and sets the protocol version;
:meth:`Connection.parameters` asks ``GetParameters General 3D Analog Force``;
:meth:`Connection.start` sends ``StreamFrames AllFrames 3D Analog`` (``3D Force`` where a
force plate measures the force) and waits for the first frame, QTM's only answer;
:meth:`Connection.run` hands every frame to a callback until the stream ends, and says why it
ended (:class:`Ending`). Each step waits at most ``timeout_s`` for QTM and is refused in one
line naming the server (:class:`~core.errors.BadInput`) where QTM refuses it, answers
something else or stays silent, and every failure closes the connection before it is raised:
a client that gives up leaves no socket open. A frame's markers come in metres (NaN when
lost), the force device's samples as the parameters state them; a frame that does not follow
the protocol's layout ends the stream as damaged, never as a crash.

What QTM does that shapes this (its protocol documentation): it greets
with "QTM RT Interface connected"; it answers ``StreamFrames`` with no text, only frames; it
says the end of a recording only as an event ("RT from file stopped", "capture stopped"),
the end of a connection by closing it, a stall by silence; and it sends events whenever they
happen, between the answers to commands.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from core.errors import BadInput
from live.protocol.address import source_name
from live.protocol.commands import (
    GREETING,
    GetParameters,
    Plain,
    StopStreaming,
    StreamFrames,
    Version,
    command_text,
)
from live.protocol.packets import (
    Component,
    Event,
    Packet,
    PacketReader,
    PacketType,
    ProtocolError,
    decode_3d,
    decode_analog,
    decode_data,
    decode_event,
    decode_force,
    encode_command,
    text_of,
)
from live.protocol.parameters import SECTIONS, ForceDevice

VERSION = "1.25"                  # the protocol version asked for (QTM 2019 and later)
DEVICE_COMPONENTS = {"analog": Component.ANALOG, "force": Component.FORCE}  # by its name
END_EVENTS: dict[int, str] = {Event.RT_FROM_FILE_STOPPED: "QTM stopped playing the file",
                              Event.CAPTURE_STOPPED: "QTM stopped capturing",
                              Event.CONNECTION_CLOSED: "QTM closed the connection",
                              Event.QTM_SHUTTING_DOWN: "QTM is shutting down"}
READ_BYTES = 1 << 16
POLL_S = 0.05                     # how often a running stream checks its deadlines
CLOSE_S = 1.0                     # the longest a polite goodbye may take


@dataclass(frozen=True)
class Frame:
    """One frame as it arrived: its number and QTM's timestamp (us), the 3D markers (M, 3) in
    metres (NaN when lost), and the force device's samples (a board's, a plate's): the first
    one's number and the values (n, C), or None where the frame carries none."""

    number: int
    timestamp_us: int
    markers: np.ndarray
    first_sample: int | None
    force: np.ndarray | None


def decode_frame(payload: bytes, device_id: int, component: str = "analog") -> Frame:
    """A data packet's payload as a :class:`Frame`; ``device_id`` picks the analog board
    (``component`` "analog") or the force plate ("force"). Bytes that do not follow the
    protocol's layout are a :class:`~live.protocol.packets.ProtocolError`."""
    data = decode_data(payload)
    body = data.components.get(Component.THREE_D)
    markers = np.empty((0, 3)) if body is None else decode_3d(body).astype(np.float64) * 1e-3
    first, force = None, None
    body = data.components.get(DEVICE_COMPONENTS[component])
    if body is not None:
        blocks = [(b.device_id, b.first_sample, b.values) for b in decode_analog(body)] \
            if component == "analog" else \
            [(b.plate_id, b.first_force, b.values) for b in decode_force(body)]
        for number, first_sample, values in blocks:
            if number == device_id and len(values):
                first, force = int(first_sample), values.astype(np.float64)
                break
    return Frame(int(data.frame), int(data.timestamp_us), markers, first, force)


@dataclass(frozen=True)
class Ending:
    """Why a stream ended, in words; ``lost``: the connection ended without QTM saying so;
    ``damage``: what was wrong with the packet that ended it (None: none)."""

    why: str
    lost: bool = False
    damage: str | None = None


class Connection:
    """One connection to a QTM real-time server, from :func:`connect` to :meth:`close`."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter,
                 source: str, timeout_s: float) -> None:
        self.source, self.timeout_s = source, timeout_s
        self._reader, self._writer = reader, writer
        self._packets = PacketReader()
        self._queue: list[Packet] = []
        self._streaming = False
        self._ending: Ending | None = None
        self._done = asyncio.Event()
        self._device: ForceDevice | None = None      # what the stream carries, once started
        self._last_frame = 0.0
        self._clock = asyncio.get_running_loop().time

    async def parameters(self) -> str:
        """The capture's parameters document (QTM's XML) for :data:`SECTIONS`."""
        reply = await self._ask(GetParameters(SECTIONS), "its parameters")
        if reply.type != PacketType.XML:
            raise BadInput(self.source, "answered GetParameters with no parameters document "
                                        f"({text_of(reply.payload)!r})")
        return text_of(reply.payload)

    async def start(self, device: ForceDevice) -> None:
        """Ask for every frame's 3D markers and the component that carries ``device`` (its
        analog board's, its force plate's); returns once the first frame has arrived (it is
        handed on first by :meth:`run`)."""
        self._device = device
        self._send(StreamFrames((Component.THREE_D, DEVICE_COMPONENTS[device.component])))
        self._streaming = True
        deadline = self._clock() + self.timeout_s
        while True:
            packet = await self._next(f"sent no frame within {self.timeout_s:g} s of "
                                      "StreamFrames", deadline)
            if packet.type == PacketType.DATA:
                self._queue.insert(0, packet)
                return
            if packet.type == PacketType.ERROR:
                raise BadInput(self.source, f"refused to stream frames: "
                                            f"{text_of(packet.payload)}")
            if packet.type == PacketType.NO_MORE_DATA:
                raise BadInput(self.source, "has no frames to stream (no more data: is QTM "
                                            "capturing, or playing a file in real time?)")
            if packet.type == PacketType.EVENT and \
                    (why := END_EVENTS.get(decode_event(packet.payload))) is not None:
                raise BadInput(self.source, f"sent no frame: {why}")

    async def run(self, on_frame: Callable[[Frame], None], duration_s: float | None
                  ) -> Ending:
        """Hand every frame to ``on_frame`` until ``duration_s``, an end event, a lost
        connection, a damaged packet, ``timeout_s`` of silence or :meth:`stop`; what
        ``on_frame`` raises ends the stream and is raised here."""
        loop = asyncio.get_running_loop()
        start = self._last_frame = loop.time()
        pump = asyncio.ensure_future(self._pump(on_frame))
        try:
            while not self._done.is_set():
                if duration_s is not None and loop.time() - start >= duration_s:
                    self._end(Ending(f"the duration ({duration_s:g} s) was reached"))
                elif loop.time() - self._last_frame > self.timeout_s:
                    self._end(Ending(f"QTM sent nothing for {self.timeout_s:g} s"))
                else:
                    with contextlib.suppress(TimeoutError):
                        await asyncio.wait_for(self._done.wait(), POLL_S)
        finally:
            pump.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await pump
        if self._ending is None:        # _done is set with an ending, or what on_frame raised
            raise RuntimeError("the stream ended without its ending")
        return self._ending

    def stop(self, why: str) -> None:
        """End the stream (Ctrl-C, a signal, a frame refused): the frames so far are kept."""
        self._end(Ending(why))

    async def close(self) -> None:
        """Say goodbye where the connection still stands, and close it; at once, whatever
        state it is in, and more than once."""
        if not self._writer.is_closing():
            with contextlib.suppress(OSError):
                if self._streaming:
                    self._send(StopStreaming())
                self._send(Plain("byebye"))
            self._writer.close()
        try:
            await asyncio.wait_for(self._writer.wait_closed(), CLOSE_S)
        except (TimeoutError, OSError):
            self._writer.transport.abort()      # the server does not read: close unread
            await asyncio.sleep(0)              # the transport closes its socket now

    # -- the dialogue before streaming ------------------------------------------------------

    async def _greeting(self) -> None:
        deadline = self._clock() + self.timeout_s
        packet = await self._next(f"did not greet within {self.timeout_s:g} s", deadline)
        while packet.type == PacketType.EVENT:
            packet = await self._next(f"did not greet within {self.timeout_s:g} s", deadline)
        text = text_of(packet.payload)
        if packet.type == PacketType.ERROR:
            raise BadInput(self.source, f"refused the connection: {text}")
        if packet.type != PacketType.COMMAND or text != GREETING:
            raise BadInput(self.source, f"is no QTM real-time server (it said {text!r}, not "
                                        f"{GREETING!r})")

    async def _version(self) -> None:
        reply = await self._ask(Version(VERSION), f"protocol version {VERSION}")
        if reply.type != PacketType.COMMAND:
            raise BadInput(self.source, f"answered the version command with "
                                        f"{text_of(reply.payload)!r}")

    async def _ask(self, command: Version | GetParameters, what: str) -> Packet:
        """Send ``command`` and return its answer (an XML or command packet); events that
        come first are passed by; an error packet is QTM's refusal of ``what``."""
        self._send(command)
        deadline = self._clock() + self.timeout_s     # events do not extend it
        while True:
            packet = await self._next(f"did not answer {command_text(command)!r} within "
                                      f"{self.timeout_s:g} s", deadline)
            if packet.type == PacketType.ERROR:
                raise BadInput(self.source, f"refused {what}: {text_of(packet.payload)}")
            if packet.type in (PacketType.COMMAND, PacketType.XML):
                return packet

    async def _next(self, silent: str, deadline: float | None = None) -> Packet:
        """The next packet, waiting until ``deadline`` (the loop's clock; default
        ``timeout_s`` from now): bad input ``silent`` after it, or where the server closes the
        connection or sends what is no packet."""
        deadline = self._clock() + self.timeout_s if deadline is None else deadline
        while not self._queue:
            try:
                data = await asyncio.wait_for(self._reader.read(READ_BYTES),
                                              max(deadline - self._clock(), 0.0))
            except TimeoutError:
                raise BadInput(self.source, silent) from None
            except OSError as e:
                raise BadInput(self.source, f"the connection failed ({e})") from None
            if not data:
                raise BadInput(self.source, "closed the connection")
            try:
                self._queue += self._packets.feed(data)
            except ProtocolError as e:
                raise BadInput(self.source, f"sent what is no QTM RT packet ({e})") from None
        return self._queue.pop(0)

    def _send(self, command: Version | GetParameters | StreamFrames | StopStreaming | Plain
              ) -> None:
        self._writer.write(encode_command(command_text(command)))

    # -- streaming ---------------------------------------------------------------------------

    async def _pump(self, on_frame: Callable[[Frame], None]) -> None:
        """Read, and hand on, packet after packet until the stream ends; the packets before a
        damaged one are handed on first."""
        damage: ProtocolError | None = None
        try:
            while True:
                while self._queue and not self._done.is_set():
                    self._handle(self._queue.pop(0), on_frame)
                if self._done.is_set():
                    return
                if damage is not None:
                    raise damage
                data = await self._reader.read(READ_BYTES)
                if not data:
                    self._end(Ending("the connection was lost", lost=True))
                    return
                try:
                    self._queue += self._packets.feed(data)
                except ProtocolError as e:
                    self._queue += e.packets
                    damage = e
        except OSError as e:
            self._end(Ending(f"the connection was lost ({e})", lost=True))
        except ProtocolError as e:
            self._end(Ending("a damaged packet", damage=str(e)))
        except BaseException:
            self._done.set()                # what on_frame raised: :meth:`run` raises it
            raise

    def _handle(self, packet: Packet, on_frame: Callable[[Frame], None]) -> None:
        if packet.type == PacketType.DATA:
            self._last_frame = self._clock()
            d = self._device
            if d is None:                   # frames are streamed only once start() named it
                raise RuntimeError("a frame arrived before the stream was started")
            on_frame(decode_frame(packet.payload, d.device_id, d.component))
        elif packet.type == PacketType.EVENT:
            why = END_EVENTS.get(decode_event(packet.payload))
            if why is not None:
                self._end(Ending(why))
        # anything else (an unasked error, "no more data", a late answer) is passed by

    def _end(self, ending: Ending) -> None:
        if self._ending is None:
            self._ending = ending
        self._done.set()


async def connect(host: str, port: int, timeout_s: float) -> Connection:
    """A connection to the QTM real-time server at ``host``:``port`` that has greeted and
    speaks protocol :data:`VERSION`; bad input where none answers within ``timeout_s``, or it
    refuses, with the connection closed."""
    source = source_name(host, port)
    try:
        reader, writer = await asyncio.wait_for(asyncio.open_connection(host, port), timeout_s)
    except (TimeoutError, OSError) as e:
        why = "" if isinstance(e, TimeoutError) else f"{e.strerror or e}: "
        raise BadInput(source, f"no QTM real-time server answered within {timeout_s:g} s "
                               f"({why}is QTM running, with real-time output on this port?)"
                       ) from None
    connection = Connection(reader, writer, source, timeout_s)
    try:
        await connection._greeting()
        await connection._version()
    except BaseException:
        await connection.close()
        raise
    return connection

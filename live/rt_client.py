"""The QTM real-time client: the vendor's SDK (``qtm-rt``) for the connection, our decoding of
each frame into numpy arrays.

The SDK connects, negotiates the protocol version, asks for the parameters and starts the
stream (``StreamFrames AllFrames 3D Analog``, or ``3D Force`` where a force plate measures the
force); each data packet is handed to :func:`decode_frame`, which reads the 3D component
(markers in mm as float32, NaN when lost) and the force's device with numpy: the analog
component (per board: channel count, sample count, the first sample's number, then the samples
channel after channel) or the force component (per plate: force count, the first force's
number, then each force's nine float32 values), so that a 500 Hz stream costs microseconds a
frame. Observed behaviour of the SDK that shapes this module (see FINDINGS):

- ``connect`` returns None, rather than raising, when nothing answers or the version is
  refused, and hangs on a server that never answers: it is given a deadline here;
- the end of a recording shows only as an event (QTM's "RT from file stopped", or "capture
  stopped"), the end of a connection as the SDK's disconnect callback, a stalled server as
  silence: each ends the stream with its reason.
"""

from __future__ import annotations

import asyncio
import struct
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from core.errors import BadInput

VERSION = "1.25"                  # the protocol version asked for (QTM 2019 and later)
DATA_HEADER = struct.Struct("<qII")          # timestamp (us), frame number, component count
COMPONENT = struct.Struct("<II")             # size (header included), type
THREE_D, ANALOG, FORCE = 1, 3, 4             # component types
COMPONENTS = {"analog": ANALOG, "force": FORCE}   # a force device's component, by name
MARKERS_HEADER = struct.Struct("<IHH")       # marker count, 2D drop rate, out-of-sync rate
DEVICES = struct.Struct("<I")                # analog boards (force plates) in the component
DEVICE = struct.Struct("<III")               # board id, channel count, sample count
FIRST_SAMPLE = struct.Struct("<I")
PLATE = struct.Struct("<III")                # plate id, force count, first force's number
PLATE_VALUES = 9                             # force, moment, application point: x y z each
END_EVENTS = {"EventRTfromFileStopped": "QTM stopped playing the file",
              "EventCaptureStopped": "QTM stopped capturing",
              "EventConnectionClosed": "QTM closed the connection",
              "EventQTMShuttingDown": "QTM is shutting down"}


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


def decode_frame(data: bytes, device_id: int, component: str = "analog") -> Frame:
    """A data packet's payload (after the packet header) as a :class:`Frame`; ``device_id``
    picks the analog board (``component`` "analog") or the force plate ("force"). A payload
    cut short is a :class:`ValueError`."""
    timestamp, number, count = DATA_HEADER.unpack_from(data, 0)
    pos, markers, first, force = DATA_HEADER.size, np.empty((0, 3)), None, None
    wanted = COMPONENTS[component]
    for _ in range(count):
        size, kind = COMPONENT.unpack_from(data, pos)
        if size < COMPONENT.size or pos + size > len(data):
            raise ValueError(f"frame {number}: component of {size} bytes past the packet's end")
        body = pos + COMPONENT.size
        if kind == THREE_D:
            markers = _markers(data, body)
        elif kind == wanted:
            first, force = _DEVICE_READERS[kind](data, body, device_id)
        pos += size
    return Frame(int(number), int(timestamp), markers, first, force)


def _markers(data: bytes, pos: int) -> np.ndarray:
    n = MARKERS_HEADER.unpack_from(data, pos)[0]
    xyz = np.frombuffer(data, "<f4", count=3 * n, offset=pos + MARKERS_HEADER.size)
    return xyz.reshape(n, 3).astype(np.float64) * 1e-3


def _analog(data: bytes, pos: int, device_id: int) -> tuple[int | None, np.ndarray | None]:
    (devices,), pos = DEVICES.unpack_from(data, pos), pos + DEVICES.size
    for _ in range(devices):
        board, channels, samples = DEVICE.unpack_from(data, pos)
        pos += DEVICE.size
        if samples == 0:
            continue
        first = FIRST_SAMPLE.unpack_from(data, pos)[0]
        pos += FIRST_SAMPLE.size
        if board == device_id:
            values = np.frombuffer(data, "<f4", count=channels * samples, offset=pos)
            return int(first), values.reshape(channels, samples).T.astype(np.float64)
        pos += 4 * channels * samples
    return None, None


def _plate(data: bytes, pos: int, plate_id: int) -> tuple[int | None, np.ndarray | None]:
    (plates,), pos = DEVICES.unpack_from(data, pos), pos + DEVICES.size
    for _ in range(plates):
        plate, forces, first = PLATE.unpack_from(data, pos)
        pos += PLATE.size
        if plate == plate_id and forces:
            values = np.frombuffer(data, "<f4", count=PLATE_VALUES * forces, offset=pos)
            return int(first), values.reshape(forces, PLATE_VALUES).astype(np.float64)
        pos += 4 * PLATE_VALUES * forces
    return None, None


_DEVICE_READERS = {ANALOG: _analog, FORCE: _plate}


class Stream:
    """A connection to a QTM real-time server that hands each frame to ``on_frame`` until the
    stream ends; :attr:`ended` says why."""

    def __init__(self, host: str, port: int, timeout_s: float) -> None:
        self.host, self.port, self.timeout_s = host, port, timeout_s
        self.source = f"QTM RT {host}:{port}"
        self.ended: str | None = None
        self.lost = False             # the connection ended without QTM saying so
        self._conn = None
        self._done: asyncio.Event | None = None
        self._last_packet = 0.0

    async def connect(self) -> bytes:
        """Connect and return the capture's parameters (XML); bad input where no server
        answers within the deadline."""
        import qtm_rt

        self._done = asyncio.Event()
        try:
            self._conn = await asyncio.wait_for(qtm_rt.connect(
                self.host, port=self.port, version=VERSION, on_event=self._on_event,
                on_disconnect=self._on_disconnect, timeout=self.timeout_s), self.timeout_s)
        except (TimeoutError, OSError):
            self._conn = None
        if self._conn is None:
            raise BadInput(self.source, f"no QTM real-time server answered within "
                                        f"{self.timeout_s:g} s (is QTM running, with "
                                        "real-time output on this port?)")
        try:
            return await self._conn.get_parameters(["general", "3d", "analog", "force"])
        except Exception as e:  # noqa: BLE001 - the SDK raises its own and asyncio's kinds
            raise BadInput(self.source, f"did not give its parameters ({type(e).__name__})"
                           ) from None

    async def run(self, on_frame: Callable[[bytes], None], duration_s: float | None,
                  component: str = "analog") -> None:
        """Stream every frame (3D and the force's ``component``, "analog" or "force") to
        ``on_frame`` (the packet's payload) until ``duration_s``, an end event, a lost
        connection or ``timeout_s`` of silence."""
        from qtm_rt.packet import QRTPacket

        loop = asyncio.get_running_loop()
        self._last_packet = loop.time()

        def packet(p: QRTPacket) -> None:
            self._last_packet = loop.time()
            on_frame(p.data)

        try:
            await self._conn.stream_frames(components=["3d", component], on_packet=packet)
        except Exception as e:  # noqa: BLE001 - the SDK raises its own and asyncio's kinds
            raise BadInput(self.source, f"refused to stream frames ({type(e).__name__}: "
                                        f"{e})") from None
        start = loop.time()
        while not self._done.is_set():
            if duration_s is not None and loop.time() - start >= duration_s:
                self._end(f"the duration ({duration_s:g} s) was reached")
            elif loop.time() - self._last_packet > self.timeout_s:
                self._end(f"QTM sent nothing for {self.timeout_s:g} s")
            else:
                await asyncio.sleep(0.05)

    def stop(self, why: str) -> None:
        """End the stream (Ctrl-C, a signal): the frames received so far are kept."""
        self._end(why)

    async def close(self) -> None:
        """Leave the server politely where the connection still stands."""
        if self._conn is not None and self._conn.has_transport():
            try:
                await asyncio.wait_for(self._conn.stream_frames_stop(), 1.0)
            except Exception:  # noqa: BLE001, S110 - leaving anyway
                pass
            self._conn.disconnect()

    def _on_event(self, event: object) -> None:
        name = getattr(event, "name", str(event))
        if name in END_EVENTS:
            self._end(END_EVENTS[name])

    def _on_disconnect(self, exc: Exception | None) -> None:
        self.lost = self.ended is None
        self._end("the connection was lost" + (f" ({exc})" if exc else ""))

    def _end(self, why: str) -> None:
        if self.ended is None:
            self.ended = why
        if self._done is not None:
            self._done.set()

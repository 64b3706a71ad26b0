"""The live client's frame: a data packet (encoded by the protocol's module, whose bytes
test_packets.py holds against the documented layout) decoded into metres and the chosen
board's or plate's samples; a packet cut anywhere, or corrupted, is a ProtocolError and never
anything else. The client's dialogue and its failures: tests/live/session/test_live_failures.py."""

from __future__ import annotations

import asyncio
import contextlib
import time

import numpy as np
import pytest

from core.errors import BadInput
from live.protocol.client import connect, decode_frame
from live.protocol.commands import GREETING
from live.protocol.packets import (
    AnalogBlock,
    Event,
    ForceBlock,
    PacketReader,
    ProtocolError,
    encode_3d,
    encode_analog,
    encode_command,
    encode_data,
    encode_event,
    encode_force,
    text_of,
)
from live.protocol.parameters import AnalogDevice


def _payload(number: int, markers: np.ndarray, boards: list[AnalogBlock],
             plates: list[ForceBlock] = ()) -> bytes:
    """A data packet's payload (after its 8-byte header): 3D, analog and force components."""
    packet = encode_data(123456, number, [encode_3d(markers), encode_analog(boards),
                                          encode_force(plates)])
    return packet[8:]


def test_a_frame_decodes_to_metres_and_the_chosen_boards_samples() -> None:
    mm = np.array([[10.5, -20.25, 3.0], [np.nan, np.nan, np.nan]])
    other, mine = np.arange(6.0).reshape(3, 2), np.array([[0.5, -1.5], [2.25, 4.0]])
    frame = decode_frame(_payload(7, mm, [AnalogBlock(1, 0, other), AnalogBlock(3, 40, mine)]),
                         device_id=3)
    assert (frame.number, frame.timestamp_us, frame.first_sample) == (7, 123456, 40)
    np.testing.assert_array_equal(frame.markers, mm / 1000.0)
    np.testing.assert_array_equal(frame.force, mine)
    assert decode_frame(_payload(8, mm, [AnalogBlock(1, 0, other)]), device_id=3).force is None
    empty = _payload(8, mm, [AnalogBlock(3, 0, np.empty((0, 2)))])      # no samples this frame
    assert decode_frame(empty, device_id=3).force is None


def test_a_frame_decodes_the_chosen_plates_forces() -> None:
    """The force component's plate of that id: its first force's number and its forces (n, 9),
    force by force; the analog component is not read then."""
    mm = np.zeros((1, 3))
    other, mine = np.arange(9.0)[None], np.arange(18.0).reshape(2, 9) / 4
    data = _payload(7, mm, [AnalogBlock(2, 0, np.ones((2, 2)))],
                    [ForceBlock(1, 5, other), ForceBlock(2, 40, mine)])
    frame = decode_frame(data, device_id=2, component="force")
    assert frame.first_sample == 40
    np.testing.assert_array_equal(frame.force, mine)
    assert decode_frame(_payload(8, mm, [], [ForceBlock(1, 0, other)]), 2, "force").force is None
    assert decode_frame(_payload(8, mm, [], [ForceBlock(2, 3, other[:0])]), 2,
                        "force").force is None


@pytest.mark.parametrize("component", ["analog", "force"])
def test_a_frame_cut_anywhere_is_a_protocol_error(component) -> None:
    data = _payload(7, np.zeros((2, 3)), [AnalogBlock(3, 0, np.zeros((2, 2)))],
                    [ForceBlock(3, 0, np.zeros((2, 9)))])
    for end in range(len(data)):
        with pytest.raises(ProtocolError):
            decode_frame(data[:end], device_id=3, component=component)


def test_corrupted_bytes_decode_or_are_a_protocol_error() -> None:
    """Any byte of a frame replaced by any value (seeded): decoded, or a ProtocolError; never
    a struct or numpy error, never a frame whose arrays run past the packet."""
    data = _payload(7, np.ones((3, 3)), [AnalogBlock(3, 5, np.ones((4, 6)))],
                    [ForceBlock(3, 2, np.ones((2, 9)))])
    rng = np.random.default_rng(0)
    decoded = 0
    for _ in range(3000):
        spoilt = bytearray(data)
        spoilt[rng.integers(len(data))] = rng.integers(256)
        try:
            frame = decode_frame(bytes(spoilt), device_id=3,
                                 component=("analog", "force")[rng.integers(2)])
        except ProtocolError:
            continue
        decoded += 1
        assert frame.markers.size * 4 <= len(data)
    assert 0 < decoded < 3000


def _scripted(handler) -> tuple[asyncio.AbstractServer, int]:
    """A server on a free port whose connections ``handler(reader, writer)`` serves."""
    async def start() -> tuple[asyncio.AbstractServer, int]:
        server = await asyncio.start_server(handler, "127.0.0.1", 0)
        return server, server.sockets[0].getsockname()[1]
    return start()


def test_events_do_not_keep_a_silent_server_waiting() -> None:
    """A server that greets, then only sends events every 0.2 s and never answers the version:
    refused once the step's 1 s has passed, not kept waiting by each event."""
    async def handler(reader, writer) -> None:
        writer.write(encode_command(GREETING))
        with contextlib.suppress(ConnectionError):
            for _ in range(40):
                writer.write(encode_event(Event.CAPTURE_STARTED))
                await writer.drain()
                await asyncio.sleep(0.2)
        writer.close()

    async def run() -> float:
        server, port = await _scripted(handler)
        tic = time.perf_counter()
        with pytest.raises(BadInput, match="did not answer"):
            await connect("127.0.0.1", port, 1.0)
        server.close()
        return time.perf_counter() - tic

    assert asyncio.run(run()) < 3.0


def test_a_recording_that_ends_before_its_first_frame_says_so_at_once() -> None:
    """QTM stops playing the file before a frame is sent: the stream start is refused in its
    words, without waiting out the timeout."""
    async def handler(reader, writer) -> None:
        writer.write(encode_command(GREETING))
        packets = PacketReader()
        while data := await reader.read(1024):
            for p in packets.feed(data):
                text = text_of(p.payload)
                if text.startswith("Version"):
                    writer.write(encode_command("Version set to 1.25"))
                elif text.startswith("StreamFrames"):
                    writer.write(encode_event(Event.RT_FROM_FILE_STOPPED))
        writer.close()

    async def run() -> float:
        server, port = await _scripted(handler)
        connection = await connect("127.0.0.1", port, 5.0)
        tic = time.perf_counter()
        with pytest.raises(BadInput, match="QTM stopped playing the file"):
            await connection.start(AnalogDevice(1, "board", 1000.0, ["a"], ["V"]))
        await connection.close()
        server.close()
        return time.perf_counter() - tic

    assert asyncio.run(run()) < 2.0

"""The live client's frame: a data packet (encoded by the protocol's module, whose bytes
test_packets.py holds against the documented layout) decoded into metres and the chosen
board's or plate's samples; a packet cut anywhere, or corrupted, is a ProtocolError and never
anything else. The client's dialogue and its failures: tests/live/session/test_live_failures.py."""

from __future__ import annotations

import numpy as np
import pytest

from live.protocol.client import decode_frame
from live.protocol.packets import (
    AnalogBlock,
    ForceBlock,
    ProtocolError,
    encode_3d,
    encode_analog,
    encode_data,
    encode_force,
)


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

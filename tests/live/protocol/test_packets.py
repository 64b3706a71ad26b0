"""The QTM RT wire format: each packet the server sends, decoded here by a reader written from
the protocol's layout with struct alone (not with the module's own structs), one tiny frame
written out byte by byte, every packet round-tripped through the module's own encoders and
decoders, and the packet reader on a stream cut anywhere."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from live.protocol.packets import (
    AnalogBlock,
    Component,
    Event,
    ForceBlock,
    PacketReader,
    PacketType,
    ProtocolError,
    decode_3d,
    decode_3d_no_labels,
    decode_analog,
    decode_data,
    decode_event,
    decode_force,
    encode_3d,
    encode_3d_no_labels,
    encode_analog,
    encode_command,
    encode_data,
    encode_error,
    encode_event,
    encode_force,
    encode_no_more_data,
    encode_xml,
    text_of,
)


def _header(packet: bytes) -> tuple[int, int, bytes]:
    """(size, type, payload) of one whole packet; the size must be the packet's length."""
    size, kind = struct.unpack_from("<II", packet, 0)
    assert size == len(packet)
    return size, kind, packet[8:]


def _components(payload: bytes) -> tuple[int, int, dict[int, bytes]]:
    """A data payload's timestamp, frame number and component bodies by type."""
    timestamp, frame, count = struct.unpack_from("<qII", payload, 0)
    pos, bodies = 16, {}
    for _ in range(count):
        size, kind = struct.unpack_from("<II", payload, pos)
        bodies[kind] = payload[pos + 8:pos + size]
        pos += size
    assert pos == len(payload)
    return timestamp, frame, bodies


def _floats(body: bytes, pos: int, n: int) -> tuple[list[float], int]:
    return list(struct.unpack_from(f"<{n}f", body, pos)), pos + 4 * n


@pytest.mark.parametrize("encode, kind", [(encode_command, 1), (encode_error, 0),
                                          (encode_xml, 2)])
def test_text_packets_end_in_one_nul(encode, kind):
    size, got, payload = _header(encode("Version set to 1.25 é"))
    assert got == kind and payload == "Version set to 1.25 é".encode() + b"\0"
    assert text_of(payload) == "Version set to 1.25 é" and size == 8 + len(payload)


def test_event_and_no_more_data():
    assert _header(encode_event(Event.RT_FROM_FILE_STOPPED)) == (9, 6, bytes([9]))
    assert _header(encode_no_more_data()) == (8, 4, b"")
    assert {e.name: e.value for e in Event}["CAPTURE_STOPPED"] == 4


def test_data_packet_with_every_component():
    markers = np.array([[1.5, -2.25, 3.0], [np.nan, np.nan, np.nan], [1e4, 0.0, -7.125]])
    analog = [AnalogBlock(3, 41, np.arange(6.0).reshape(3, 2)),       # 3 samples, 2 channels
              AnalogBlock(4, 99, np.empty((0, 5)))]                    # no samples this frame
    forces = [ForceBlock(1, 7, np.arange(18.0).reshape(2, 9))]
    packet = encode_data(-1_500_000, 123, [
        encode_3d(markers), encode_3d_no_labels(markers[[0, 2]], np.array([1, 3])),
        encode_analog(analog), encode_force(forces)])
    _, kind, payload = _header(packet)
    timestamp, frame, bodies = _components(payload)
    assert (kind, timestamp, frame, sorted(bodies)) == (3, -1_500_000, 123, [1, 2, 3, 4])

    count, drop, sync = struct.unpack_from("<IHH", bodies[1], 0)
    xyz, end = _floats(bodies[1], 8, 9)
    assert (count, drop, sync, end) == (3, 0, 0, len(bodies[1]))
    np.testing.assert_array_equal(np.reshape(xyz, (3, 3)), markers.astype(np.float32))

    count = struct.unpack_from("<I", bodies[2], 0)[0]
    rows = [struct.unpack_from("<3fI", bodies[2], 8 + 16 * i) for i in range(count)]
    assert count == 2 and len(bodies[2]) == 8 + 16 * count
    assert [r[3] for r in rows] == [1, 3] and rows[1][:3] == (1e4, 0.0, -7.125)

    body = bodies[3]
    devices, pos = struct.unpack_from("<I", body, 0)[0], 4
    device, channels, samples, first = struct.unpack_from("<IIII", body, pos)
    values, pos = _floats(body, pos + 16, channels * samples)
    assert (devices, device, channels, samples, first) == (2, 3, 2, 3, 41)
    assert values == [0, 2, 4, 1, 3, 5]                     # channel after channel
    assert struct.unpack_from("<III", body, pos) == (4, 5, 0)  # no first sample number
    assert pos + 12 == len(body)

    plates, plate, n, number = struct.unpack_from("<IIII", bodies[4], 0)
    values, pos = _floats(bodies[4], 16, 9 * n)
    assert (plates, plate, n, number, values, pos) == (1, 1, 2, 7, list(range(18)), 88)


def test_vendor_client_reads_the_analog_component_alike():
    """The vendor SDK's own decoding of the same bytes: a reader that is not ours."""
    from qtm_rt.packet import QRTPacket

    values = np.array([[0.5, -1.0], [2.0, 4.0]])
    packet = encode_data(0, 1, [encode_analog([AnalogBlock(1, 10, values)])])
    analog = QRTPacket(packet[8:]).get_analog()[1]
    assert [(d.id, n.sample_number, c.samples) for d, n, c in analog] == [
        (1, 10, (0.5, 2.0)), (1, 10, (-1.0, 4.0))]


def test_reader_waits_for_a_whole_packet():
    packets = [encode_command("QTM RT Interface connected"), encode_event(Event.TRIGGER),
               encode_no_more_data(), encode_data(5, 6, [encode_3d(np.zeros((2, 3)))])]
    stream = b"".join(packets)
    reader, got = PacketReader(), []
    for i in range(len(stream)):                 # one byte at a time: cut everywhere
        got += reader.feed(stream[i:i + 1])
        whole = sum(1 for k in range(len(packets)) if len(b"".join(packets[:k + 1])) <= i + 1)
        assert len(got) == whole
    assert [(p.type, p.payload) for p in got] == [(_header(p)[1], p[8:]) for p in packets]
    assert reader.pending == 0
    assert reader.feed(packets[0][:5]) == [] and reader.pending == 5


@pytest.mark.parametrize("size", [0, 7, 1 << 30])
def test_reader_refuses_an_impossible_size(size):
    with pytest.raises(ProtocolError, match=f"packet of {size} bytes"):
        PacketReader().feed(struct.pack("<II", size, 1) + b"x" * 8)


def test_markers_are_float32_millimetres_with_nan_kept():
    body = encode_3d(np.array([[math.pi, np.nan, -0.0]]))[8:]
    x, y, z = struct.unpack_from("<3f", body, 8)
    assert x == np.float32(math.pi) and math.isnan(y) and z == 0.0


def test_one_tiny_frame_is_the_documented_bytes():
    """A frame of one marker at (1, 2, 3) mm, written out byte by byte from the documented
    layout: what the module encodes, and what it decodes."""
    tiny = bytes.fromhex(
        "34000000" "03000000"               # packet: 52 bytes, type 3 (data)
        "e803000000000000"                  # timestamp: 1000 us
        "05000000" "01000000"               # frame 5, one component
        "1c000000" "01000000"               # component: 28 bytes, type 1 (3D)
        "01000000" "0000" "0000"            # one marker, drop rates 0
        "0000803f" "00000040" "00004040")   # x, y, z: 1.0, 2.0, 3.0 (f32)
    assert encode_data(1000, 5, [encode_3d(np.array([[1.0, 2.0, 3.0]]))]) == tiny
    data = decode_data(tiny[8:])
    assert (data.timestamp_us, data.frame, list(data.components)) == (1000, 5, [1])
    np.testing.assert_array_equal(decode_3d(data.components[1]), [[1.0, 2.0, 3.0]])


def test_every_packet_round_trips():
    """Encoded, split off a stream and decoded: the same texts, event, markers (float32, NaN
    kept), ids, analog devices (an empty one's first sample read as 0) and plates."""
    markers = np.array([[1.5, -2.25, 3.0], [np.nan, np.nan, np.nan]], np.float32)
    boards = [AnalogBlock(3, 41, np.arange(6.0).reshape(3, 2)),
              AnalogBlock(4, 0, np.empty((0, 5)))]
    plates = [ForceBlock(1, 7, np.arange(18.0).reshape(2, 9)), ForceBlock(2, 9, np.empty((0, 9)))]
    stream = encode_command("Version 1.25") + encode_error("no") + encode_xml("<a/>") + \
        encode_event(Event.CAPTURE_STOPPED) + encode_no_more_data() + encode_data(
            -5, 9, [encode_3d(markers), encode_3d_no_labels(markers[:1], np.array([7])),
                    encode_analog(boards), encode_force(plates)])
    packets = PacketReader().feed(stream)
    assert [p.type for p in packets] == [PacketType.COMMAND, PacketType.ERROR, PacketType.XML,
                                         PacketType.EVENT, PacketType.NO_MORE_DATA,
                                         PacketType.DATA]
    assert [text_of(p.payload) for p in packets[:3]] == ["Version 1.25", "no", "<a/>"]
    assert decode_event(packets[3].payload) == Event.CAPTURE_STOPPED
    data = decode_data(packets[5].payload)
    assert (data.timestamp_us, data.frame) == (-5, 9)
    c = data.components
    np.testing.assert_array_equal(decode_3d(c[Component.THREE_D]), markers)
    xyz, ids = decode_3d_no_labels(c[Component.THREE_D_NO_LABELS])
    np.testing.assert_array_equal(xyz, markers[:1])
    assert ids.tolist() == [7]
    for got, want in zip(decode_analog(c[Component.ANALOG]), boards, strict=True):
        assert (got.device_id, got.first_sample) == (want.device_id, want.first_sample)
        np.testing.assert_array_equal(got.values, want.values)
    for got, want in zip(decode_force(c[Component.FORCE]), plates, strict=True):
        assert (got.plate_id, got.first_force) == (want.plate_id, want.first_force)
        np.testing.assert_array_equal(got.values, want.values)


def test_the_reader_hands_on_the_packets_before_a_damaged_one():
    good = encode_command("a") + encode_command("b")
    with pytest.raises(ProtocolError, match="packet of 0 bytes") as refused:
        PacketReader().feed(good + bytes(8))
    assert [text_of(p.payload) for p in refused.value.packets] == ["a", "b"]

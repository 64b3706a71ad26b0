"""The live client's parts on hand-made input: QTM's parameters document, a data packet's
bytes written here with struct from the protocol's layout, the journal cut short, and the
session's checks against QTM's labels and analog board (force plates: test_live_plate.py)."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from core.errors import BadInput
from data_schema.session import read_session
from live.live_journal import FORCE, MARKERS, Journal, read_journal
from live.live_layout import live_layout
from live.qtm_parameters import (
    AnalogDevice,
    ForcePlate,
    QtmParameters,
    device_from_json,
    device_json,
    parse_parameters,
)
from live.rt_client import decode_frame

SOURCE = "QTM RT 127.0.0.1:1"
XML = """<QTM_Parameters_Ver_1.25>
 <General><Frequency>500</Frequency><Capture_Time>10</Capture_Time></General>
 <The_3D><AxisUpwards>+Z</AxisUpwards><Labels>2</Labels>
  <Label><Name>P00</Name><RGBColor>255</RGBColor></Label>
  <Label><Name>Indenter - 1</Name><RGBColor>255</RGBColor></Label></The_3D>
 <Analog><Device><Device_ID>3</Device_ID><Device_Name>USB-2533</Device_Name>
  <Channels>2</Channels><Frequency>1000</Frequency>
  <Channel><Label>G0</Label><Unit>V</Unit></Channel>
  <Channel><Label>G1</Label><Unit>V</Unit></Channel></Device></Analog>
</QTM_Parameters_Ver_1.25>\0"""


def test_the_parameters_document_gives_rates_labels_and_boards() -> None:
    p = parse_parameters(XML.encode(), SOURCE)
    assert (p.rate_hz, p.labels) == (500.0, ["P00", "Indenter - 1"])
    assert p.analog == [AnalogDevice(3, "USB-2533", 1000.0, ["G0", "G1"], ["V", "V"])]
    words = XML.replace("<Unit>V</Unit>", "<Unit>newtons</Unit>", 1)   # QTM's word for N
    assert parse_parameters(words, SOURCE).analog[0].units == ["N", "V"]


@pytest.mark.parametrize(("edit", "words"), [
    (("<Frequency>500</Frequency>", "<Frequency>0</Frequency>"), "General/Frequency"),
    (("<Name>P00</Name>", ""), None),
    (("</QTM_Parameters_Ver_1.25>", ""), "not XML"),
])
def test_a_document_without_rates_or_labels_is_refused(edit, words) -> None:
    xml = XML.replace(*edit)
    if words is None:            # a label without a name is kept as "", a document of none
        xml = XML.split("<Label>")[0] + "</The_3D></QTM_Parameters_Ver_1.25>"
        words = "name no marker"
    with pytest.raises(BadInput, match=words):
        parse_parameters(xml, SOURCE)


PLATE_XML = """<QTM_Parameters_Ver_1.25>
 <General><Frequency>500</Frequency></General>
 <The_3D><Labels>1</Labels><Label><Name>P00</Name></Label></The_3D>
 <Force><Unit_Length>m</Unit_Length><Unit_Force>N</Unit_Force>
  <Plate><Plate_ID>2</Plate_ID><Analog_Device_ID>1</Analog_Device_ID>
   <Frequency>1000.000000</Frequency><Type>Kistler</Type><Name>Force-plate 1</Name>
   <Length>0.6</Length><Width>0.5</Width>
   <Location><Corner1><X>0.3</X><Y>0.25</Y><Z>0</Z></Corner1>
    <Corner2><X>-0.3</X><Y>0.25</Y><Z>0</Z></Corner2>
    <Corner3><X>-0.3</X><Y>-0.25</Y><Z>0</Z></Corner3>
    <Corner4><X>0.3</X><Y>-0.25</Y><Z>0</Z></Corner4></Location></Plate>
  <Plate><Force_Plate_Index>3</Force_Plate_Index><Frequency>500</Frequency></Plate>
 </Force>
</QTM_Parameters_Ver_1.25>"""
NINE = ["Force_X", "Force_Y", "Force_Z", "Moment_X", "Moment_Y", "Moment_Z", "COP_X", "COP_Y",
        "COP_Z"]


def test_the_parameters_document_gives_the_force_plates() -> None:
    """Each plate's id (Plate_ID, or Force_Plate_Index of protocols before 1.8), rate, name,
    type and corners (in mm, whatever Unit_Length), its nine values in the units stated."""
    p = parse_parameters(PLATE_XML, SOURCE)
    assert p.analog == []
    first, second = p.plates
    corners = [[300.0, 250.0, 0.0], [-300.0, 250.0, 0.0], [-300.0, -250.0, 0.0],
               [300.0, -250.0, 0.0]]
    assert first == ForcePlate(2, "Force-plate 1", 1000.0, NINE, ["N"] * 3 + ["N*m"] * 3
                               + ["m"] * 3, "Kistler", corners)
    assert (second.device_id, second.name, second.rate_hz, second.corners_mm) == \
        (3, "#2", 500.0, None)
    assert device_from_json(device_json(first)) == first
    assert device_from_json({"device_id": 3, "name": "b", "rate_hz": 1.0, "labels": [],
                             "units": []}) == AnalogDevice(3, "b", 1.0, [], [])
    with pytest.raises(BadInput, match="force plate #2 Frequency"):
        parse_parameters(PLATE_XML.replace("<Frequency>500</Frequency></Plate>", "</Plate>"),
                         SOURCE)


def _packet(number: int, markers: np.ndarray, boards: list[tuple[int, int, np.ndarray]],
            plates: list[tuple[int, int, np.ndarray]] = ()) -> bytes:
    """A data packet's payload from the protocol's layout: i64 timestamp, u32 frame, u32
    components; 3D: u32 count, u16 drop, u16 sync, f32 x y z (mm); analog: u32 boards, per
    board u32 id, u32 channels, u32 samples, u32 first sample, f32 channel after channel;
    force: u32 plates, per plate u32 id, u32 forces, u32 first force, 9 f32 per force."""
    three = struct.pack("<IHH", len(markers), 0, 0) + markers.astype("<f4").tobytes()
    analog = struct.pack("<I", len(boards))
    for board, first, values in boards:
        analog += struct.pack("<IIII", board, values.shape[1], values.shape[0], first)
        analog += values.T.astype("<f4").tobytes()
    force = struct.pack("<I", len(plates))
    for plate, first, values in plates:
        force += struct.pack("<III", plate, len(values), first) + values.astype("<f4").tobytes()
    comps = [struct.pack("<II", 8 + len(body), kind) + body for kind, body in
             ((1, three), (3, analog), (4, force))]
    return struct.pack("<qII", 123456, number, len(comps)) + b"".join(comps)


def test_a_frame_decodes_to_metres_and_the_chosen_boards_samples() -> None:
    mm = np.array([[10.5, -20.25, 3.0], [np.nan, np.nan, np.nan]])
    other, mine = np.arange(6.0).reshape(3, 2), np.array([[0.5, -1.5], [2.25, 4.0]])
    frame = decode_frame(_packet(7, mm, [(1, 0, other), (3, 40, mine)]), device_id=3)
    assert frame.number == 7 and frame.first_sample == 40
    np.testing.assert_array_equal(frame.markers, mm / 1000.0)
    np.testing.assert_array_equal(frame.force, mine)
    assert decode_frame(_packet(8, mm, [(1, 0, other)]), device_id=3).force is None


def test_a_frame_decodes_the_chosen_plates_forces() -> None:
    """The force component's plate of that id: its first force's number and its forces (n, 9),
    force by force; the analog component is not read then."""
    mm = np.zeros((1, 3))
    other, mine = np.arange(9.0)[None], np.arange(18.0).reshape(2, 9) / 4
    data = _packet(7, mm, [(2, 0, np.ones((2, 2)))], [(1, 5, other), (2, 40, mine)])
    frame = decode_frame(data, device_id=2, component="force")
    assert frame.first_sample == 40
    np.testing.assert_array_equal(frame.force, mine)
    assert decode_frame(_packet(8, mm, [], [(1, 0, other)]), 2, "force").force is None
    assert decode_frame(_packet(8, mm, [], [(2, 3, other[:0])]), 2, "force").force is None
    with pytest.raises((ValueError, struct.error)):
        decode_frame(data[:-5], device_id=2, component="force")


def test_a_frame_cut_short_is_refused() -> None:
    data = _packet(7, np.zeros((2, 3)), [(3, 0, np.zeros((2, 2)))])
    with pytest.raises((ValueError, struct.error)):
        decode_frame(data[:-5], device_id=3)


def test_the_journal_keeps_every_complete_block_of_a_file_cut_short(tmp_path: Path) -> None:
    path = tmp_path / "session.mcap.part"
    journal = Journal(path, {"labels": ["a"], "channels": ["c0", "c1"]})
    for i in range(3):
        journal.append(MARKERS, np.arange(i * 5, i * 5 + 5) * 2_000_000, np.full((5, 3), i))
        before = path.stat().st_size
        journal.append(FORCE, np.arange(i * 10, i * 10 + 10) * 1_000_000, np.full((10, 2), i))
    cut = (before + path.stat().st_size) // 2   # the last block cut short, as by a kill
    journal.close()
    whole = read_journal(path)
    assert whole.complete and len(whole.streams[MARKERS][0]) == 15
    np.testing.assert_array_equal(whole.streams[MARKERS][0], np.arange(15) * 2_000_000)
    (tmp_path / "cut.part").write_bytes(path.read_bytes()[:cut])
    part = read_journal(tmp_path / "cut.part")
    assert not part.complete
    assert len(part.streams[MARKERS][0]) == 15 and len(part.streams[FORCE][0]) == 20
    (tmp_path / "other.part").write_bytes(b"\x89MCAP0\r\n")
    with pytest.raises(BadInput, match="not a live session's journal"):
        read_journal(tmp_path / "other.part")


def test_the_session_is_held_against_qtms_labels_and_boards(twin_session: Path) -> None:
    cfg = read_session(twin_session)
    labels = cfg.mocap.phantom_markers + cfg.mocap.indenter_markers + ["stray"]
    gauges = AnalogDevice(2, "USB-2533", 1000.0, list(cfg.force.channels), ["V"] * 6)
    emg = AnalogDevice(1, "EMG", 2000.0, ["e0", "e1"], ["V", "V"])
    assert live_layout(QtmParameters(SOURCE, 500.0, labels, [emg, gauges]), cfg).device == gauges
    with pytest.raises(BadInput, match="not in file: P03"):
        live_layout(QtmParameters(SOURCE, 500.0, [n for n in labels if n != "P03"],
                                  [gauges]), cfg)
    newtons = AnalogDevice(2, "USB-2533", 1000.0, list(cfg.force.channels), ["N"] * 6)
    with pytest.raises(BadInput, match="is in N as the file states, but force.units says V"):
        live_layout(QtmParameters(SOURCE, 500.0, labels, [newtons]), cfg)
    with pytest.raises(BadInput, match="no analog board"):
        live_layout(QtmParameters(SOURCE, 500.0, labels, []), cfg)


def test_presses_are_found_as_the_samples_arrive() -> None:
    """Three raised cosines on a 1 kHz force, fed a frame (2 samples) at a time: peaks 6, 0.4
    (below detect: a touch) and 3 N, a flicker below contact inside the first (one contact)."""
    from live.live_presses import PressTracker

    rate, t = 1000.0, np.arange(12000) / 1000.0
    force = np.zeros_like(t)
    for start, peak in ((1.0, 6.0), (5.0, 0.4), (8.0, 3.0)):
        inside = (t >= start) & (t < start + 2.0)
        force[inside] = peak * 0.5 * (1 - np.cos(np.pi * (t[inside] - start)))
    force[1500:1510] = 0.0                        # 10 ms below contact: the same contact
    tracker, done = PressTracker(rate, detect_n=0.5, contact_n=0.05), []
    times = np.round(t * 1e9).astype(np.int64)
    for i in range(0, len(t), 2):
        done += tracker.add(times[i:i + 2], force[i:i + 2])
    assert [d.number for d in done] == [1, 2]
    assert [round(d.peak_n, 3) for d in done] == [6.0, 3.0]
    assert [d.peak_ns for d in done] == [2_000_000_000, 9_000_000_000]
    assert abs(done[0].start_ns - 1.0e9) < 0.2e9 and abs(done[1].end_ns - 10.0e9) < 0.2e9

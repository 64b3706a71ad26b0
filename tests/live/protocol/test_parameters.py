"""QTM's parameters document read into plain fields: the marker rate, the labels, the analog
boards and the force plates; a document without rates or labels refused in one line."""

from __future__ import annotations

import pytest

from core.errors import BadInput
from live.protocol.parameters import (
    AnalogDevice,
    ForcePlate,
    device_from_json,
    device_json,
    parse_parameters,
)

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

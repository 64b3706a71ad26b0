"""What a QTM real-time server says of its capture: the answer to ``GetParameters General 3D
Analog Force`` (QTM's XML), read into plain fields.

QTM states the marker rate in ``General/Frequency``, the 3D labels in ``The_3D/Label/Name``
(in the order the 3D component sends the markers), per analog board (``Analog/Device``) its
name, rate and channels with their labels and units (``Channel/Label``, ``Channel/Unit``), and
per force plate (``Force/Plate``) its id (``Plate_ID``; ``Force_Plate_Index`` before protocol
1.8), name, type, rate and corners (``Location/Corner1`` .. ``Corner4``), with the units of
every plate (``Force/Unit_Force``, ``Force/Unit_Length``). A plate's force component carries
nine values a sample, named here as QTM's force export names them (``Force_X`` .. ``COP_Z``):
the force in ``Unit_Force``, its moment in ``Unit_Force`` m (as QTM's export writes N m) and
its point of application in ``Unit_Length``. A document without the rate or the labels, or a
board or plate without its id or rate, is bad input naming the server: nothing of a capture
can be trusted without its labels and rates.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass, field
from typing import Any, ClassVar

from core.errors import BadInput
from core.units import length_scale
from ingest.qtm_force_plate import COLUMNS

# the words QTM writes for units (an analog channel's), as ours
QTM_WORDS = {"newtons": "N", "newtonmetre": "N*m", "newtonmetres": "N*m"}
# the sections of the document a live session asks for and the replay serves, in QTM's order
SECTIONS = ("general", "3d", "analog", "force")


@dataclass(frozen=True)
class AnalogDevice:
    """One analog board: its id, name, sample rate and channels (labels, units)."""

    device_id: int
    name: str
    rate_hz: float
    labels: list[str]
    units: list[str]
    component: ClassVar[str] = "analog"      # the data component that streams it
    what: ClassVar[str] = "analog board"


@dataclass(frozen=True)
class ForcePlate:
    """One force plate: its id, name, sample rate, the nine values of each sample (labels,
    units), its type and its corners (lab, mm) where stated."""

    device_id: int                           # Plate_ID
    name: str
    rate_hz: float
    labels: list[str]
    units: list[str]
    type: str = ""
    corners_mm: list[list[float]] | None = None
    component: ClassVar[str] = "force"
    what: ClassVar[str] = "force plate"


ForceDevice = AnalogDevice | ForcePlate      # what streams a session's force


@dataclass(frozen=True)
class QtmParameters:
    """A capture's marker rate and labels, its analog boards and force plates, as the server
    stated them."""

    source: str                      # "QTM RT host:port": what messages name
    rate_hz: float
    labels: list[str]
    analog: list[AnalogDevice]
    plates: list[ForcePlate] = field(default_factory=list)


def parse_parameters(xml: str | bytes, source: str) -> QtmParameters:
    """The capture ``xml`` (QTM's parameters document) describes; ``source`` names the server
    in a refusal."""
    text = xml.decode("utf-8", "replace") if isinstance(xml, bytes) else xml
    try:
        root = ET.fromstring(text.rstrip("\0").strip())
    except ET.ParseError as e:
        raise BadInput(source, f"its parameters are not XML ({e})") from None
    rate = _number(root.findtext("General/Frequency"), source, "General/Frequency")
    labels = [(label.findtext("Name") or "").strip() for label in root.iterfind("The_3D/Label")]
    if not labels:
        raise BadInput(source, "its 3D parameters name no marker (The_3D/Label)")
    force_unit = _word(root.findtext("Force/Unit_Force") or "N")
    length_unit = _word(root.findtext("Force/Unit_Length") or "mm")
    return QtmParameters(source, rate, labels,
                         [_device(d, source) for d in root.iterfind("Analog/Device")],
                         [_plate(p, i + 1, source, force_unit, length_unit)
                          for i, p in enumerate(root.iterfind("Force/Plate"))])


def device_json(device: ForceDevice) -> dict[str, Any]:
    """A device as plain values (a journal's header), its component with it."""
    return {"component": device.component, **asdict(device)}


def device_from_json(d: dict[str, Any]) -> ForceDevice:
    """The device :func:`device_json` wrote (an analog board where it names no component)."""
    fields = {k: v for k, v in d.items() if k != "component"}
    return (ForcePlate if d.get("component") == "force" else AnalogDevice)(**fields)


def _device(node: ET.Element, source: str) -> AnalogDevice:
    name = (node.findtext("Device_Name") or "").strip()
    where = f"analog device {name or node.findtext('Device_ID')}"
    channels = node.findall("Channel")
    return AnalogDevice(
        device_id=int(_number(node.findtext("Device_ID"), source, f"{where} Device_ID")),
        name=name, rate_hz=_number(node.findtext("Frequency"), source, f"{where} Frequency"),
        labels=[(c.findtext("Label") or "").strip() for c in channels],
        units=[_word(c.findtext("Unit") or "") for c in channels])


def _plate(node: ET.Element, index: int, source: str, force_unit: str, length_unit: str
           ) -> ForcePlate:
    name = (node.findtext("Name") or "").strip() or f"#{index}"
    where = f"force plate {name}"
    plate_id = node.findtext("Plate_ID") or node.findtext("Force_Plate_Index")
    return ForcePlate(
        device_id=int(_number(plate_id, source, f"{where} Plate_ID")), name=name,
        rate_hz=_number(node.findtext("Frequency"), source, f"{where} Frequency"),
        labels=list(COLUMNS),
        units=[force_unit] * 3 + [f"{force_unit}*m"] * 3 + [length_unit] * 3,
        type=(node.findtext("Type") or "").strip(), corners_mm=_corners_mm(node, length_unit))


def _corners_mm(node: ET.Element, unit: str) -> list[list[float]] | None:
    """A plate's four corners (``Location/Corner1`` .. ``Corner4``, X Y Z) in mm; None unless
    all twelve are numbers in a length unit."""
    try:
        mm = length_scale(unit) * 1e3
        return [[_float(node.findtext(f"Location/Corner{k}/{a}")) * mm for a in "XYZ"]
                for k in range(1, 5)]
    except (TypeError, ValueError):
        return None


def _float(text: str | None) -> float:
    """The number an element of the document holds; ValueError where there is none."""
    if text is None:
        raise ValueError("no such element")
    return float(text)


def _word(text: str) -> str:
    """A unit as QTM words it, in ours (``newtons``: N)."""
    text = text.strip()
    return QTM_WORDS.get(text.lower(), text)


def _number(text: str | None, source: str, what: str) -> float:
    """A positive finite number from the document, or bad input naming the element."""
    try:
        value = _float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise BadInput(source, f"its parameters lack a positive {what} (got {text!r})")
    return value

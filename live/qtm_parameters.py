"""What a QTM real-time server says of its capture: the answer to ``GetParameters General 3D
Analog`` (QTM's XML), read into plain fields.

QTM states the marker rate in ``General/Frequency``, the 3D labels in ``The_3D/Label/Name``
(in the order the 3D component sends the markers), and per analog board (``Analog/Device``)
its name, rate and channels with their labels and units (``Channel/Label``, ``Channel/Unit``).
A document without them is bad input naming the server: nothing of a capture can be trusted
without its labels and rates.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass

from core.errors import BadInput


@dataclass(frozen=True)
class AnalogDevice:
    """One analog board: its id, name, sample rate and channels (labels, units)."""

    device_id: int
    name: str
    rate_hz: float
    labels: list[str]
    units: list[str]


@dataclass(frozen=True)
class QtmParameters:
    """A capture's marker rate and labels and its analog boards, as the server stated them."""

    source: str                      # "QTM RT host:port": what messages name
    rate_hz: float
    labels: list[str]
    analog: list[AnalogDevice]


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
    return QtmParameters(source, rate, labels,
                         [_device(d, source) for d in root.iterfind("Analog/Device")])


def _device(node: ET.Element, source: str) -> AnalogDevice:
    name = (node.findtext("Device_Name") or "").strip()
    where = f"analog device {name or node.findtext('Device_ID')}"
    channels = node.findall("Channel")
    return AnalogDevice(
        device_id=int(_number(node.findtext("Device_ID"), source, f"{where} Device_ID")),
        name=name, rate_hz=_number(node.findtext("Frequency"), source, f"{where} Frequency"),
        labels=[(c.findtext("Label") or "").strip() for c in channels],
        units=[(c.findtext("Unit") or "").strip() for c in channels])


def _number(text: str | None, source: str, what: str) -> float:
    """A positive finite number from the document, or bad input naming the element."""
    try:
        value = float(text)
    except (TypeError, ValueError):
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise BadInput(source, f"its parameters lack a positive {what} (got {text!r})")
    return value

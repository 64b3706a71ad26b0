"""The replay's answer to ``GetParameters``: QTM's parameters document for a replayed session.

The element names are QTM's (RT protocol documentation; the vendor's clients read the same
names): the marker rate in ``General/Frequency`` (with ``Capture_Time``), the marker labels in
``The_3D`` (``Labels``, then one ``Label/Name`` each, in the order the 3D component sends
them), the analog device in ``Analog/Device`` (``Device_ID``, ``Device_Name``, ``Channels``,
``Frequency``, then per channel ``Channel/Label`` and ``Channel/Unit``) where an analog device
carries the force, and ``Force`` (``Unit_Length`` mm, ``Unit_Force`` N) with one ``Plate``
where a force plate measured it (``Plate_ID``, ``Analog_Device_ID`` 0: no analog device is
served, ``Frequency``, ``Type``, ``Name``, and where the session knows the corners
``Length``, ``Width``, ``Location/Corner1`` .. ``Corner4`` (lab, mm) and ``Origin`` 0 0 0: the
plate's origin on its top surface, where the replay puts the point of application). A real
QTM sends much more (cameras, trigger settings, marker colours, bones, the analog board's
range, a plate's channels and calibration matrix, the calibration time); a client should read
nothing of that from the replay. Example::

    <QTM_Parameters_Ver_1.25>
      <General>
        <Frequency>500</Frequency>
        <Capture_Time>10.268</Capture_Time>
      </General>
      <The_3D>
        <Labels>2</Labels>
        <Label><Name>P00</Name></Label>
        <Label><Name>P01</Name></Label>
      </The_3D>
      ...
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence

import numpy as np

from live.protocol.parameters import SECTIONS
from live.replay.source import ReplaySource

DEVICE_ID = 1                                        # the force's analog device
PLATE_ID = 1                                         # ... or its force plate
FORCE_UNITS = {"Unit_Length": "mm", "Unit_Force": "N"}


def parameters_xml(source: ReplaySource, sections: Sequence[str], version: str) -> str:
    """The parameters document of ``sections`` (of :data:`SECTIONS`, in their order) under
    the root ``QTM_Parameters_Ver_<version>``."""
    root = ET.Element(f"QTM_Parameters_Ver_{version}")
    for name in SECTIONS:
        if name in sections:
            _WRITERS[name](ET.SubElement(root, _ELEMENT[name]), source)
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode")


def _number(x: float) -> str:
    """A rate or duration as QTM writes it: whole numbers without a decimal point."""
    return str(int(x)) if float(x).is_integer() else repr(float(x))


def _add(parent: ET.Element, tag: str, text: str) -> ET.Element:
    node = ET.SubElement(parent, tag)
    node.text = text
    return node


def _general(node: ET.Element, source: ReplaySource) -> None:
    _add(node, "Frequency", _number(source.rate_hz))
    _add(node, "Capture_Time", f"{source.frames / source.rate_hz:.3f}")


def _three_d(node: ET.Element, source: ReplaySource) -> None:
    _add(node, "Labels", str(len(source.labels)))
    for label in source.labels:
        _add(ET.SubElement(node, "Label"), "Name", label)


def _analog(node: ET.Element, source: ReplaySource) -> None:
    a = source.force
    if a.plate is not None:
        return
    device = ET.SubElement(node, "Device")
    _add(device, "Device_ID", str(DEVICE_ID))
    _add(device, "Device_Name", a.name)
    _add(device, "Channels", str(len(a.labels)))
    _add(device, "Frequency", _number(a.rate_hz))
    for label, unit in zip(a.labels, a.units, strict=True):
        channel = ET.SubElement(device, "Channel")
        _add(channel, "Label", label)
        _add(channel, "Unit", unit)


def _force(node: ET.Element, source: ReplaySource) -> None:
    for tag, unit in FORCE_UNITS.items():
        _add(node, tag, unit)
    f = source.force
    if f.plate is None:
        return
    plate = ET.SubElement(node, "Plate")
    for tag, text in (("Plate_ID", str(PLATE_ID)), ("Analog_Device_ID", "0"),
                      ("Frequency", _number(f.rate_hz)), ("Type", f.plate.type or "unknown"),
                      ("Name", f.name)):
        _add(plate, tag, text)
    if f.plate.corners_mm is not None:
        _location(plate, f.plate.corners_mm)


def _location(plate: ET.Element, corners_mm: list[list[float]]) -> None:
    """A plate's size, its corners 1 to 4 (lab, mm) and its origin (0: on its top surface)."""
    c = np.asarray(corners_mm, float)
    _add(plate, "Length", f"{np.linalg.norm(c[0] - c[1]):.6f}")
    _add(plate, "Width", f"{np.linalg.norm(c[1] - c[2]):.6f}")
    location = ET.SubElement(plate, "Location")
    for k, corner in enumerate(c, start=1):
        _xyz(ET.SubElement(location, f"Corner{k}"), corner)
    _xyz(ET.SubElement(plate, "Origin"), np.zeros(3))


def _xyz(node: ET.Element, xyz: np.ndarray) -> None:
    for axis, v in zip("XYZ", xyz, strict=True):
        _add(node, axis, f"{v:.6f}")


_ELEMENT = {"general": "General", "3d": "The_3D", "analog": "Analog", "force": "Force"}
_WRITERS: dict[str, Callable[[ET.Element, ReplaySource], None]] = {
    "general": _general, "3d": _three_d, "analog": _analog, "force": _force}

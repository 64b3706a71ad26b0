"""Force through the mocap system's analog board: analog channels of a C3D file or of a QTM
analog TSV export (``<trial>_a.tsv``), on the mocap's own clock.

Both readers (:func:`ingest.c3d.read_c3d_analog`, :func:`ingest.qtm_analog.read_qtm_analog`) give
an :class:`AnalogExport`: every channel in the physical units the file states, with the scale
factors that were applied. :func:`analog_force` picks the six gauge or wrench channels that
``session.toml`` names (by name or by 1-based channel number) and returns them as a
:class:`~core.series.ForceSeries` in SI units, marked as sharing the mocap's clock
(``meta["clock"] = "mocap"``), so that sync has no offset or drift to estimate.

Channel names: C3D's ``ANALOG:LABELS`` are short (QTM and others cut them, or repeat one label
over the six channels of a force plate); a label that is repeated, or that is only the start
of its ``ANALOG:DESCRIPTIONS`` entry, gives way to the description.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from core.errors import BadInput
from core.series import SHARED_CLOCK, ForceSeries
from ingest.channel_scale import to_si

_RATE_TOLERANCE = 1e-6           # relative: an analog rate this close to k x the point rate is k


@dataclass
class AnalogExport:
    """The analog channels of one export, in the units the file states (scales applied)."""

    source: str
    format: str                    # "c3d" or "qtm_tsv_analog"
    labels: list[str]              # (C,) as the file has them (C3D ANALOG:LABELS)
    descriptions: list[str]        # (C,) C3D ANALOG:DESCRIPTIONS ("" where absent)
    units: list[str]               # (C,) as the file states them ("" where it does not)
    scales: np.ndarray             # (C,) channel scale (C3D ANALOG:SCALE, QTM CHANNEL_GAIN)
    offsets: np.ndarray            # (C,) C3D ANALOG:OFFSET (0 for QTM TSV)
    gen_scale: float               # C3D ANALOG:GEN_SCALE (1 for QTM TSV)
    rate_hz: float
    values: np.ndarray             # (T, C) float64: (raw - offset) * scale * gen_scale
    point_rate_hz: float | None = None    # the same file's 3D frame rate (C3D)
    meta: dict[str, Any] = field(default_factory=dict)
    numbers: np.ndarray | None = None     # (T,) each sample's number from the first, where
    #                                       the file counts them (QTM's SAMPLE; a skip is a
    #                                       hole of lost samples); None: consecutive

    @property
    def names(self) -> list[str]:
        """One name per channel: its label, or its description where the label is cut short
        or repeated (and the description is not)."""
        return channel_names(self.labels, self.descriptions)

    @property
    def samples(self) -> int:
        return int(self.values.shape[0])

    def time_ns(self) -> np.ndarray:
        """Sample times (int64 ns), 0 at the first 3D frame, on the mocap's clock (a hole of
        lost samples stays a jump)."""
        numbers = np.arange(self.samples) if self.numbers is None else self.numbers
        return np.round(numbers * (1e9 / self.rate_hz)).astype(np.int64)

    def summary(self) -> dict[str, Any]:
        """What ``pipeline inspect`` lists: the rate, and each channel's name, units, scales."""
        per_frame = None if self.point_rate_hz is None else self.rate_hz / self.point_rate_hz
        how = ("(raw - ANALOG:OFFSET) x ANALOG:SCALE x ANALOG:GEN_SCALE" if self.format == "c3d"
               else "as written (CHANNEL_GAIN)")
        return {"rate_hz": self.rate_hz, "samples": self.samples, "values": how,
                "samples_per_frame": per_frame, "gen_scale": self.gen_scale,
                "channels": [{"number": i + 1, "name": n, "label": lab, "description": d,
                              "units": u, "scale": float(s), "offset": float(o)}
                             for i, (n, lab, d, u, s, o) in enumerate(zip(
                                 self.names, self.labels, self.descriptions, self.units,
                                 self.scales, self.offsets, strict=True))]}


def channel_names(labels: Sequence[str], descriptions: Sequence[str]) -> list[str]:
    """Each channel's label, or its description where the label is repeated among the labels
    or is a proper prefix of the description (cut short), and the description is unique."""
    out = []
    for lab, desc in zip(labels, descriptions, strict=True):
        repeated = labels.count(lab) > 1 or not lab
        cut = bool(desc) and desc != lab and desc.startswith(lab)
        usable = bool(desc) and descriptions.count(desc) == 1
        out.append(desc if (repeated or cut) and usable else lab)
    return out


def check_scales(path: str | Path, what: str, scales: np.ndarray, n: int) -> None:
    """Channel scale factors: one per channel, each a finite non-zero number."""
    if scales.size < n:
        raise BadInput(path, f"{what} has {scales.size} values for {n} analog channels")
    bad = np.flatnonzero(~np.isfinite(scales[:n]) | (scales[:n] == 0))
    if bad.size:
        i = int(bad[0])
        raise BadInput(path, f"{what} of analog channel {i + 1} is {scales[i]:g}, not a scale "
                             "factor (a non-zero number)")


def samples_per_frame(path: str | Path, analog_hz: float, point_hz: float) -> int:
    """Analog samples per 3D frame; an analog rate that is not a whole multiple of the point
    rate is bad input (the two could not share one clock)."""
    ratio = analog_hz / point_hz if point_hz > 0 else float("nan")
    k = round(ratio) if np.isfinite(ratio) else 0
    if k < 1 or abs(ratio - k) > _RATE_TOLERANCE * ratio:
        raise BadInput(path, f"analog rate {analog_hz:g} Hz is not a whole multiple of the "
                             f"point rate {point_hz:g} Hz")
    return int(k)


def resolve_channels(export: AnalogExport, wanted: Sequence[str | int],
                     what: str = "force.channels") -> list[int]:
    """0-based indices of the channels ``wanted`` names: a name (as :attr:`AnalogExport.names`
    gives it, or a label that is unique) or a 1-based channel number."""
    names, labels = export.names, export.labels
    out = []
    for w in wanted:
        if isinstance(w, int):
            if not 1 <= w <= len(names):
                raise BadInput(export.source, f"{what}: channel number {w} is not in the file "
                                              f"(channels 1 to {len(names)})")
            out.append(w - 1)
        elif names.count(w) == 1:
            out.append(names.index(w))
        elif labels.count(w) == 1:
            out.append(labels.index(w))
        else:
            why = "names several channels" if names.count(w) > 1 or labels.count(w) > 1 else \
                "is not in the file"
            shown = ", ".join(names[:12]) + (" ..." if len(names) > 12 else "")
            raise BadInput(export.source, f"analog channel {w!r} ({what} in session.toml) "
                                          f"{why}; the file has: {shown}")
    return out


def file_units(export: AnalogExport) -> list[str]:
    """The units the export states per channel ("" where it states none: a C3D without
    ANALOG:UNITS, a QTM analog TSV without CHANNEL_UNITS, whose V is only QTM's default)."""
    if export.meta.get("units_stated") is False:
        return [""] * len(export.units)
    return list(export.units)


def analog_force(export: AnalogExport, channels: Sequence[str | int], kind: str,
                 rate_hz: float | None = None, trigger: str | int | None = None,
                 units: str | list[str] | None = None, scale: Sequence[float] | None = None,
                 offset: Sequence[float] | None = None) -> ForceSeries:
    """The six force channels (and a trigger) of an analog export as a ``ForceSeries`` in SI
    units on the mocap's clock. ``rate_hz``, when given (session.toml), must be the file's;
    ``units`` (session.toml's, None where it states none) name the channels' units where the
    export states none (else V), and ``scale``/``offset`` turn volts into N and N m
    (:mod:`ingest.channel_scale`)."""
    if rate_hz is not None and not np.isclose(rate_hz, export.rate_hz, rtol=_RATE_TOLERANCE):
        raise BadInput(export.source, f"session.toml says the analog rate is {rate_hz:g} Hz "
                                      f"but the file says {export.rate_hz:g} Hz")
    idx = resolve_channels(export, channels)
    stated = file_units(export)
    given = [stated[i] or ("" if units is not None or scale is not None else "V")
             for i in idx]
    names = [export.names[i] for i in idx]
    values, si_units, info = to_si(export.source, export.values[:, idx], names, given, kind,
                                   units, scale, offset)
    trig = None
    if trigger is not None:
        trig = export.values[:, resolve_channels(export, [trigger], "force.trigger_column")[0]]
    meta = {"format": export.format, "clock": SHARED_CLOCK, **info,
            "units_in_file": [export.units[i] for i in idx],
            "analog_channels": [i + 1 for i in idx], "analog_rate_hz": export.rate_hz,
            "scales": [float(export.scales[i]) for i in idx],
            "offsets": [float(export.offsets[i]) for i in idx],
            "gen_scale": export.gen_scale}
    return ForceSeries(source=export.source, time_ns=export.time_ns(), channels=names,
                       values=values, units=si_units, kind=kind, rate_hz=export.rate_hz,
                       trigger=None if trig is None else trig.copy(), meta=meta)

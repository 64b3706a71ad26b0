"""Force channels into SI: the units the file states, the ``units`` session.toml states, and an
optional per-channel ``scale`` and ``offset`` (an F/T interface's calibrated analog output in
volts: N/V and N m/V are its settings).

For each channel, with ``v`` the value as the file has it:

- without a scale, the channel is in the file's stated unit, else in session.toml's ``units``,
  else the kind's default (V for gauges; N, N, N, N*m, N*m, N*m for a wrench); a file and a
  session.toml that state different units are refused;
- with a scale, the channel is ``(v - offset) * scale`` in session.toml's ``units`` (default by
  kind), where ``v`` is first taken to V (or N, N*m) when the file states a unit, so a scale is
  per volt whatever prefix the file writes.

The result must be volts for a gauge log and forces and torques for a wrench.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from core.errors import BadInput
from core.units import channel_units, unit_to_si


def _si(source: str | Path, unit: str, name: str, what: str) -> tuple[float, str]:
    try:
        return unit_to_si(unit)
    except ValueError:
        raise BadInput(source, f"channel {name!r}: {what} {unit!r} is not a force, torque or "
                               "voltage unit") from None


def _per_channel(source: str | Path, v: Sequence[float] | None, n: int, key: str,
                 default: float) -> np.ndarray:
    if v is None:
        return np.full(n, default)
    arr = np.asarray(v, dtype=np.float64).ravel()
    if arr.size == 1:
        arr = np.full(n, arr[0])
    if arr.size != n:
        raise BadInput(source, f"force.{key} has {arr.size} values for {n} channels")
    return arr


def to_si(source: str | Path, values: np.ndarray, names: Sequence[str],
          file_units: Sequence[str], kind: str, units: str | list[str] | None = None,
          scale: Sequence[float] | None = None, offset: Sequence[float] | None = None,
          ) -> tuple[np.ndarray, list[str], dict[str, object]]:
    """``values`` (T, C) as the file has them -> (values in SI, SI units, what was done).

    ``file_units`` holds "" where the file states none; ``units`` is session.toml's (None
    where it states none).
    """
    n = len(names)
    try:
        stated = channel_units(units, kind, n) if units is not None else None
        defaults = channel_units(None, kind, n)
    except ValueError as e:
        raise BadInput(source, f"force.units: {e}") from None
    scales = _per_channel(source, scale, n, "scale", 1.0)
    offsets = _per_channel(source, offset, n, "offset", 0.0)
    if not np.all(np.isfinite(scales) & (scales != 0)) or not np.all(np.isfinite(offsets)):
        raise BadInput(source, "force.scale must be finite non-zero numbers and force.offset "
                               "finite numbers")
    out = np.empty(values.shape, dtype=np.float64)
    si_units, used = [], []
    for i, name in enumerate(names):
        fu = file_units[i]
        if scale is None and offset is None:
            unit = fu or (stated[i] if stated else defaults[i])
            if fu and stated and _si(source, fu, name, "the file's unit") != \
                    _si(source, stated[i], name, "force.units"):
                raise BadInput(source, f"channel {name!r} is in {fu} as the file states, but "
                                       f"force.units says {stated[i]}")
            factor, si = _si(source, unit, name, "the file's unit" if fu else "force.units")
            out[:, i] = values[:, i] * factor
        else:
            pre = _si(source, fu, name, "the file's unit")[0] if fu else 1.0
            unit = stated[i] if stated else defaults[i]
            factor, si = _si(source, unit, name, "force.units")
            out[:, i] = (values[:, i] * pre - offsets[i]) * scales[i] * factor
        if si not in (("V",) if kind == "gauge" else ("N", "N*m")):
            hint = " (give force.scale in N/V and N m/V, and force.units)" if si == "V" else ""
            raise BadInput(source, f"channel {name!r} is in {unit}, which does not fit "
                                   f"force.kind = {kind!r}{hint}")
        si_units.append(si)
        used.append(unit)
    info: dict[str, object] = {"units_in_file": list(file_units), "units": used}
    if scale is not None or offset is not None:
        info.update(scale=scales.tolist(), offset=offsets.tolist())
    return out, si_units, info

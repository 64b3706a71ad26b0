"""The one table of units the readers and session.toml share: time, length, force, torque, volts.

``unit_to_si`` converts force, torque and gauge-voltage units to N, N*m and V;
``LENGTH_UNITS`` are the length units mocap exports state; ``TIME_UNITS`` the units a force
log's time column may be in; ``channel_units`` turns a ``units`` setting (one unit for all
channels, a comma-separated list or a list) into one unit per channel; ``unit_in_name`` and
``time_unit_in_name`` read the unit a column's name states ("Force X (N)", "Tz [N-mm]",
"time_ms").
"""

from __future__ import annotations

import re

TIME_UNITS: dict[str, float] = {"s": 1e9, "ms": 1e6, "us": 1e3, "ns": 1.0}   # ns per unit
LENGTH_UNITS: dict[str, float] = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}          # m per unit
WRENCH_UNITS = ("N", "N", "N", "N*m", "N*m", "N*m")
KIND_UNITS = {"gauge": ("V",), "wrench": ("N", "N*m")}     # SI units a force-log kind allows

_LBF = 4.4482216152605            # N per pound-force
_INCH, _FOOT = 0.0254, 0.3048     # m
_G = 9.80665                      # m/s^2, for gram- and kilogram-force
_UNITS: dict[str, tuple[float, str]] = {
    # force -> N
    "N": (1.0, "N"), "kN": (1e3, "N"), "mN": (1e-3, "N"), "lbf": (_LBF, "N"),
    "klbf": (1e3 * _LBF, "N"), "g": (1e-3 * _G, "N"), "gf": (1e-3 * _G, "N"),
    "kg": (_G, "N"), "kgf": (_G, "N"),
    # torque -> N*m
    "N-m": (1.0, "N*m"), "N-mm": (1e-3, "N*m"), "kN-m": (1e3, "N*m"), "mN-m": (1e-3, "N*m"),
    "lbf-in": (_LBF * _INCH, "N*m"), "lbf-ft": (_LBF * _FOOT, "N*m"),
    "g-cm": (1e-5 * _G, "N*m"), "gf-cm": (1e-5 * _G, "N*m"), "kg-cm": (1e-2 * _G, "N*m"),
    "kgf-cm": (1e-2 * _G, "N*m"),
    # gauge outputs -> V
    "V": (1.0, "V"), "mV": (1e-3, "V"),
}


def unit_to_si(unit: str) -> tuple[float, str]:
    """``(factor, si_unit)`` with ``value_si = factor * value``; unknown units -> ValueError.

    Spellings ``N*m``, ``N.m``, ``Nm``, ``N m``, ``N·m`` and ``N-m`` are the same unit.
    """
    u = unit.strip().replace("·", "-").replace("*", "-").replace(".", "-").replace(" ", "-")
    if u not in _UNITS:
        for prefix in ("kN", "mN", "N", "lbf", "kgf", "gf", "kg", "g"):   # Nm, Nmm, lbfin
            rest = u[len(prefix):]
            if u.startswith(prefix) and rest in ("m", "mm", "in", "ft", "cm"):
                u = f"{prefix}-{rest}"
                break
    if u not in _UNITS:
        raise ValueError(f"unknown unit {unit!r}")
    return _UNITS[u]


def length_scale(unit: str) -> float:
    """Metres per ``unit`` (mm, cm, m); anything else -> ValueError."""
    if unit not in LENGTH_UNITS:
        raise ValueError(f"{unit!r} is not a length unit ({', '.join(LENGTH_UNITS)})")
    return LENGTH_UNITS[unit]


def channel_units(units: object, kind: str, n: int) -> list[str]:
    """One unit per channel, as given, for ``n`` channels of a ``kind`` force log.

    ``units`` is None (V for a gauge log; N, N, N, N*m, N*m, N*m for a wrench), one unit for
    every channel, a comma-separated string or a list. ValueError when it is not text, the
    count is wrong, a unit is unknown or does not fit ``kind``.
    """
    if kind not in KIND_UNITS:
        raise ValueError(f"kind must be one of {', '.join(KIND_UNITS)}, got {kind!r}")
    if units is None:
        given = ["V"] * n if kind == "gauge" else list(WRENCH_UNITS[:n])
    elif isinstance(units, str):
        given = [u.strip() for u in units.split(",")]
    elif isinstance(units, list | tuple) and all(isinstance(u, str) for u in units):
        given = [u.strip() for u in units]
    else:
        raise ValueError(f"units must be a unit or a list of units, got {units!r}")
    if len(given) == 1:
        given = given * n
    if len(given) != n:
        raise ValueError(f"{len(given)} units given for {n} channels")
    allowed = KIND_UNITS[kind]
    for u in given:
        if unit_to_si(u)[1] not in allowed:
            raise ValueError(f"unit {u!r} does not fit kind {kind!r} "
                             f"(expected {' or '.join(allowed)})")
    return given


_BRACKETED = re.compile(r"[(\[]\s*([^()\[\]]+?)\s*[)\]]\s*$")
_TIME_SUFFIX = re.compile(r"(?:^|[\s_\-])(s|ms|us|ns|sec|msec|usec|nsec)$", re.IGNORECASE)
_TIME_WORDS = {"sec": "s", "msec": "ms", "usec": "us", "nsec": "ns", "µs": "us", "μs": "us"}


def unit_in_name(name: str) -> str | None:
    """The force, torque or voltage unit a column's name states in brackets at its end
    ("Force X (N)", "Tz [N-mm]", "G0 (mV)"), as written; None when it states none we know."""
    m = _BRACKETED.search(name)
    if m is None:
        return None
    try:
        unit_to_si(m.group(1))
    except ValueError:
        return None
    return m.group(1)


def time_unit_in_name(name: str) -> str | None:
    """The time unit (s, ms, us, ns) a time column's name states: "time (ms)", "t [s]",
    "time_ms", "Time us"; None when it states none."""
    m = _BRACKETED.search(name) or _TIME_SUFFIX.search(name.strip())
    if m is None:
        return None
    u = m.group(1).strip()
    u = _TIME_WORDS.get(u.lower(), u)
    return u if u in TIME_UNITS else None

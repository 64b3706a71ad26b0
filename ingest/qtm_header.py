"""What each key of a QTM TSV header must hold, so that a header that cannot be right is refused
before any of the file is trusted.

QTM writes its header as ``KEY<tab>value...`` lines. A value that is not what its key needs
(``FREQUENCY abc``, ``NO_OF_FRAMES 2.5``), keys that contradict each other (``NO_OF_MARKERS 14``
over 15 ``MARKER_NAMES``, ``DATA_INCLUDED 6D`` over ``MARKER_NAMES``), or a column line that
names other markers than ``MARKER_NAMES``, in another order, would make the reader drop or shift
a marker's data without a word. The functions here judge plain values and return what is wrong
(``(key, message)`` or ``(index, message)``), or None; the reader adds the file and the line.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from datetime import datetime

COUNT_KEYS = ("NO_OF_FRAMES", "NO_OF_CAMERAS", "NO_OF_MARKERS", "NO_OF_BODIES", "NO_OF_ANALOG")
RATE_KEYS = ("FREQUENCY", "ANALOG_FREQUENCY")
ONE_VALUE_KEYS = (*COUNT_KEYS, *RATE_KEYS, "DATA_INCLUDED")
DATA_INCLUDED = {"MARKER_NAMES": "3D", "BODY_NAMES": "6D"}
_STAMP_FORMATS = ("%Y-%m-%d, %H:%M:%S.%f", "%Y-%m-%d, %H:%M:%S", "%Y-%m-%d %H:%M:%S.%f",
                  "%Y-%m-%d %H:%M:%S")
_LEADING_COLUMNS = ("Frame", "Time")
# an EVENT's time may differ from its frame's by this many frames (QTM stamps events between
# frames and prints the time with 3 decimals, hence the extra millisecond)
_EVENT_FRAMES, _EVENT_PRINT_S = 2.0, 1e-3
# the Time column may run this much off FREQUENCY (relative), plus 1 ms for printed rounding
_RATE_TOLERANCE, TIME_PRINT_S = 0.01, 1e-3

Problem = tuple[str, str]


def count(text: str) -> int | None:
    """``text`` as a whole number >= 0 (``15``, ``015``); None for anything else."""
    t = text.strip()
    return int(t) if t.isascii() and t.isdigit() else None


def finite(text: str) -> float | None:
    """``text`` as a finite number; None for anything else."""
    try:
        v = float(text)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def header_problem(keys: Mapping[str, list[str]], names_key: str) -> Problem | None:
    """The first header value that cannot be right in an export listing ``names_key``
    (``MARKER_NAMES`` or ``BODY_NAMES``), as ``(key, message)``; None when all can be."""
    for check in (_one_value, _counts, _rates, _data_included, _time_stamp):
        problem = check(keys, names_key)
        if problem is not None:
            return problem
    return None


def _one_value(keys: Mapping[str, list[str]], _names_key: str) -> Problem | None:
    for key in ONE_VALUE_KEYS:
        values = keys.get(key)
        if values is not None and (len(values) != 1 or not values[0].strip()):
            shown = "no value" if not any(v.strip() for v in values) else f"{len(values)} values"
            return key, f"{key} must hold one value, found {shown}"
    return None


def _counts(keys: Mapping[str, list[str]], _names_key: str) -> Problem | None:
    for key in COUNT_KEYS:
        if key in keys and count(keys[key][0]) is None:
            return key, f"{key} {keys[key][0].strip()!r} is not a count (a whole number >= 0)"
    return None


def _rates(keys: Mapping[str, list[str]], _names_key: str) -> Problem | None:
    if "FREQUENCY" in keys:
        rate = finite(keys["FREQUENCY"][0])
        if rate is None or rate <= 0:
            return "FREQUENCY", (f"FREQUENCY {keys['FREQUENCY'][0].strip()!r} is not a frame "
                                 "rate (a number > 0 Hz)")
    if "ANALOG_FREQUENCY" in keys:
        analog = finite(keys["ANALOG_FREQUENCY"][0])
        if analog is None or analog < 0:
            return "ANALOG_FREQUENCY", (f"ANALOG_FREQUENCY {keys['ANALOG_FREQUENCY'][0].strip()!r}"
                                        " is not a sample rate (a number >= 0 Hz)")
        channels = count(keys["NO_OF_ANALOG"][0]) if "NO_OF_ANALOG" in keys else None
        if analog == 0 and channels:
            return "ANALOG_FREQUENCY", (f"ANALOG_FREQUENCY is 0 but NO_OF_ANALOG says {channels} "
                                        "analog channels")
    return None


def _data_included(keys: Mapping[str, list[str]], names_key: str) -> Problem | None:
    said = keys["DATA_INCLUDED"][0].strip() if "DATA_INCLUDED" in keys else None
    if said is not None and said != DATA_INCLUDED[names_key]:
        return "DATA_INCLUDED", (f"DATA_INCLUDED is {said} but the header lists {names_key} "
                                 f"(a {DATA_INCLUDED[names_key]} export)")
    return None


def _time_stamp(keys: Mapping[str, list[str]], _names_key: str) -> Problem | None:
    """``TIME_STAMP  2026-01-19, 10:19:43.755  2063631.96175450``: a date and time, then
    optionally the seconds since the computer started."""
    values = keys.get("TIME_STAMP")
    if values is None:
        return None
    date = values[0].strip() if values else ""
    if len(values) > 2 or not any(_parses(date, f) for f in _STAMP_FORMATS):
        return "TIME_STAMP", (f"TIME_STAMP {date!r} is not a date and time "
                              "(YYYY-MM-DD, hh:mm:ss[.fff] [seconds])")
    if len(values) == 2 and finite(values[1]) is None:
        return "TIME_STAMP", f"TIME_STAMP seconds {values[1].strip()!r} is not a number"
    return None


def _parses(text: str, fmt: str) -> bool:
    try:
        datetime.strptime(text, fmt)
    except ValueError:
        return False
    return True


def names_problem(keys: Mapping[str, list[str]], names_key: str,
                  count_key: str) -> Problem | None:
    """MARKER_NAMES / BODY_NAMES: at least one, none empty, none twice, as many as the count key
    says; TRAJECTORY_TYPES: one non-empty entry per marker."""
    names = [n.strip() for n in keys[names_key]]
    if not names:
        return names_key, f"{names_key} lists no names"
    if not all(names):
        return names_key, f"{names_key} has an empty name (name {names.index('') + 1})"
    dups = sorted({n for n in names if names.count(n) > 1})
    if dups:
        return names_key, f"duplicate name(s) in {names_key}: {', '.join(dups)}"
    if count_key in keys and count(keys[count_key][0]) != len(names):
        return count_key, (f"{count_key} is {keys[count_key][0].strip()} but {names_key} lists "
                           f"{len(names)} names")
    types = keys.get("TRAJECTORY_TYPES")
    if types is not None and len(types) != len(names):
        return "TRAJECTORY_TYPES", (f"TRAJECTORY_TYPES has {len(types)} entries for {len(names)} "
                                    "markers")
    if types is not None and not all(t.strip() for t in types):
        return "TRAJECTORY_TYPES", "TRAJECTORY_TYPES has an empty entry"
    return None


def event_problem(label: str, frame: int, time_s: float, rate: float | None) -> str | None:
    """An ``EVENT label frame time`` line whose frame and time cannot both be right: frame 1 is
    at 0 s, so the time must lie near ``(frame - 1) / FREQUENCY``."""
    if frame < 1:
        return f"EVENT {label!r} is at frame {frame}; QTM counts frames from 1"
    if rate is None or not (math.isfinite(rate) and rate > 0 and math.isfinite(time_s)):
        return None
    expected = (frame - 1) / rate
    if abs(time_s - expected) > _EVENT_FRAMES / rate + _EVENT_PRINT_S:
        return (f"EVENT {label!r} says frame {frame} and {time_s:g} s, but frame {frame} is at "
                f"{expected:.3f} s at FREQUENCY {rate:g}")
    return None


def rate_problem(rate: float, frames: int, duration_s: float) -> str | None:
    """FREQUENCY against the Time column: ``frames`` rows spanning ``duration_s`` seconds."""
    if frames < 2:
        return None
    expected = (frames - 1) / rate
    if abs(duration_s - expected) > _RATE_TOLERANCE * expected + TIME_PRINT_S:
        return (f"FREQUENCY says {rate:g} Hz but the Time column runs at "
                f"{(frames - 1) / duration_s:.4g} Hz ({frames} frames in {duration_s:g} s)")
    return None


def column_problem(labels: list[str], names: list[str]) -> tuple[int, str] | None:
    """A 3D column line (``Frame Time <name> X <name> Y <name> Z ...``) that names other markers
    than ``names`` or puts them in another order, as ``(0-based column, message)``.

    Besides Frame and Time, every column belongs to a marker of ``names`` (``<name> X`` or a
    further per-marker column such as ``<name> Type``), each marker's columns stand together,
    and the markers come in the order of ``names``. (A marker of ``names`` with no column at all
    is the caller's to report, by the column it lacks.)
    """
    known = set(names)
    seen: set[str] = set()
    first: dict[str, int] = {}
    current = None
    for i, label in enumerate(labels):
        if label in seen:
            return i, f"column line names {label!r} twice"
        seen.add(label)
        if label in _LEADING_COLUMNS:
            continue
        marker = _marker_of(label, known)
        if marker is None:
            return i, _foreign(label)
        if marker != current and marker in first:
            return i, f"column line names marker {marker!r} in two places"
        first.setdefault(marker, i)
        current = marker
    order = list(first)
    expected = [n for n in names if n in first]
    if order != expected:
        j = next(k for k, (a, b) in enumerate(zip(order, expected, strict=True)) if a != b)
        return first[order[j]], (f"column line has marker {order[j]!r} where MARKER_NAMES has "
                                 f"{expected[j]!r}: the markers are in another order")
    return None


def _foreign(label: str) -> str:
    """What is wrong with a column label that belongs to no marker of MARKER_NAMES."""
    if label[-2:] in (" X", " Y", " Z"):
        return (f"column line names marker {label[:-2]!r} ({label!r}), which MARKER_NAMES "
                "does not list")
    return (f"column line names {label!r}, which is neither Frame, Time nor a column of a "
            "MARKER_NAMES marker")


def _marker_of(label: str, known: set[str]) -> str | None:
    """The marker of ``known`` a column label belongs to: the longest name before a space."""
    for cut in range(len(label) - 1, 0, -1):
        if label[cut] == " " and label[:cut] in known:
            return label[:cut]
    return None

"""When the frames of a QTM TSV 3D or 6D export were taken, and when its EVENT lines happened.

A frame's time comes from the Time column when there is one (it must be present, increasing,
and agree with ``FREQUENCY``), else from its index at ``FREQUENCY``; every EVENT's frame and
time must agree at the rate the data confirmed. A capture with lost frames (a hole,
:mod:`core.holes`) keeps its times as written: the rate is checked on the steps between the
holes, and sync finds the holes again from the times.
"""

from __future__ import annotations

import numpy as np

from core.holes import find_holes
from core.series import frame_times_ns, time_to_ns
from ingest.qtm_header import event_problem, rate_problem
from ingest.qtm_scan import QtmHead, key_line


def frame_times(head: QtmHead, t: np.ndarray | None, n: int) -> tuple[np.ndarray, float]:
    """Time stamps (ns) from the Time column, else frame index / FREQUENCY; and the rate."""
    freq = head.number("FREQUENCY")
    line = f"line {key_line(head, 'FREQUENCY')}"
    if t is None:
        if freq is None:
            raise head.bad("no Time column and no numeric FREQUENCY: cannot time the frames")
        return frame_times_ns(n, freq, head.path, "FREQUENCY", line), freq
    if freq is not None and not (np.isfinite(freq) and freq > 0):
        raise head.bad(f"FREQUENCY {freq:g} is not a positive rate", key_line(head, "FREQUENCY"))
    bad = np.flatnonzero(np.isnan(t))
    if bad.size:
        raise head.bad("Time is missing", head.first_line + int(bad[0]))
    ns = time_to_ns(t, head.path, where=lambda i: f"line {head.first_line + i}")
    steps = np.diff(ns)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise head.bad(f"Time is not increasing ({t[i]:g} s after {t[i - 1]:g} s, frame {i})",
                       head.first_line + i)
    timing = find_holes(ns, head.path, "frames", where=lambda i: f"line {head.first_line + i}")
    if freq is None:
        return ns, 1e9 / timing.period_ns if steps.size else float("nan")
    recorded = sum(float(ns[b - 1] - ns[a]) for a, b in timing.stretches(n))
    off = rate_problem(freq, n - len(timing.holes), recorded / 1e9)
    if off is not None:
        raise head.bad(off, key_line(head, "FREQUENCY"))
    return ns, freq


def events(head: QtmHead, rate: float) -> list[tuple[str, int]]:
    """The EVENT lines as (label, time in ns); each one's frame and time must agree at
    ``rate`` (the file's frame rate, once the data have confirmed it)."""
    for (label, frame, time), line in zip(head.events, head.event_lines, strict=True):
        what = event_problem(label, frame, time, rate)
        if what is not None:
            raise head.bad(what, line)
    ns = time_to_ns([t for _, _, t in head.events], head.path, where=lambda i: f"EVENT {i + 1}")
    return [(label, int(t)) for (label, _, _), t in zip(head.events, ns, strict=True)]

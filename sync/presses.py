"""Splitting a session into presses, naming each press's location and repeat, cutting them out.

A press runs from contact onset to release: the frames where the force magnitude stays above
a contact level (a few noise widths), in a run that rises above a detection level. What makes
a press is :class:`PressRule`, stated once here for sync on a whole recording
(:func:`segment_presses`) and ``pipeline live`` on a stream (:mod:`live.session.presses`).
Presses at the same place on the phantom (tip within ``radius`` of a location's centre,
measured in the surface plane) share a location id; locations are numbered in the order they
are first pressed, repeats within each location. Each press is then cut out of the session's
series with a margin of unloaded frames on both sides (:func:`cut_presses`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import overload

import numpy as np

from core.runs import true_runs

MIN_PRESS_S = 0.2    # a contact shorter than this is a touch, not a press (s)
MERGE_S = 0.05       # contacts apart by less than this are one: flicker at the contact level (s)


@dataclass(frozen=True)
class PressRule:
    """What makes a press, for a whole series (sync) and a stream (live) alike: a contact is
    a force above ``contact_n``; two contacts apart by less than :data:`MERGE_S` are one; a
    contact is a press when it peaks above ``detect_n`` and lasts :data:`MIN_PRESS_S`."""

    detect_n: float      # a press must rise above this force (N)
    contact_n: float     # a contact is a force above this (N)

    @overload
    def touching(self, force_n: float) -> bool: ...

    @overload
    def touching(self, force_n: np.ndarray) -> np.ndarray: ...

    def touching(self, force_n: np.ndarray | float) -> np.ndarray | bool:
        """Where the force (N) is a contact: a mask of a series, or one sample's answer."""
        return force_n > self.contact_n

    def bridges(self, gap_samples: int, rate_hz: float) -> bool:
        """Whether a gap of ``gap_samples`` samples at ``rate_hz`` below the contact level
        joins the contacts either side of it into one."""
        return gap_samples < MERGE_S * rate_hz

    def is_press(self, peak_n: float, samples: int, rate_hz: float) -> bool:
        """Whether a contact that peaked at ``peak_n`` (N) over ``samples`` samples at
        ``rate_hz`` (from its first sample above contact to its last, both counted) is a
        press."""
        return peak_n > self.detect_n and samples / rate_hz >= MIN_PRESS_S


@dataclass
class Press:
    """One press on the mocap frame index axis (``release`` is one past the last loaded frame)."""

    onset: int
    release: int
    peak: int
    location: int = -1
    repeat: int = -1


def segment_presses(force_magnitude: np.ndarray, rate_hz: float, rule: PressRule
                    ) -> tuple[list[Press], int]:
    """Complete presses in a force-magnitude series (NaN = unknown), and how many were cut off.

    Runs of contact (``rule``) that :meth:`PressRule.bridges` joins are merged (noise flicker
    at the contact level); a press is a merged run that ``rule`` calls one, its duration
    counted in samples from onset to release.
    A press that touches either end of the series or the unknown (NaN) samples before or after
    the force was recorded was cut off by the end of a recording: its onset or release is not
    known, so it is left out and only counted (the second value). Unknown samples between
    known ones (a hole in the force log) are bridged by a straight line for finding the
    presses only: a press across a hole stays one press (for the caller to leave out, as
    :mod:`sync.holes` does), and a hole at rest makes none.
    """
    f = np.asarray(force_magnitude, float)
    known = np.isfinite(f)
    inside = np.zeros(len(f), bool)
    if known.any():
        first, last = np.flatnonzero(known)[[0, -1]]
        inside[first:last + 1] = True
        f = np.where(known | ~inside, f, np.interp(np.arange(len(f)), np.flatnonzero(known),
                                                   f[known]))
        known = known | inside
    f = np.where(known, f, 0.0)
    spans: list[list[int]] = []
    for a, b in true_runs(rule.touching(f)):
        if spans and rule.bridges(a - spans[-1][1], rate_hz):
            spans[-1][1] = b
        else:
            spans.append([a, b])
    presses, cut = [], 0
    for a, b in spans:
        if not rule.is_press(float(f[a:b].max()), b - a, rate_hz):
            continue
        if a == 0 or b == len(f) or not known[a - 1 : b + 1].all():
            cut += 1
            continue
        presses.append(Press(a, b, a + int(np.argmax(f[a:b]))))
    return presses, cut


def assign_locations(centres: np.ndarray, radius: float
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Location id and repeat number of each press from its contact point (K, D).

    Greedy in press order: a press joins the nearest known location within ``radius`` (whose
    centre becomes the mean of its presses), or opens a new one. Returns (location, repeat,
    location centres (L, D)).
    """
    pts = np.asarray(centres, float)
    members: list[list[int]] = []
    loc = np.full(len(pts), -1, int)
    rep = np.full(len(pts), -1, int)
    for k, p in enumerate(pts):
        if not np.isfinite(p).all():
            continue
        if members:
            means = np.array([pts[m].mean(axis=0) for m in members])
            dist = np.linalg.norm(means - p, axis=1)
            j = int(np.argmin(dist))
            if dist[j] <= radius:
                loc[k], rep[k] = j, len(members[j])
                members[j].append(k)
                continue
        loc[k], rep[k] = len(members), 0
        members.append([k])
    means = np.array([pts[m].mean(axis=0) for m in members]) if members else np.empty(
        (0, pts.shape[1]))
    return loc, rep, means


@dataclass
class PressRecord:
    """One press, cut out with its margins, on the mocap clock."""

    press: Press                     # indices into this record's frames
    time_ns: np.ndarray
    points: np.ndarray
    force: np.ndarray
    torque: np.ndarray
    force_magnitude: np.ndarray
    depth: np.ndarray
    quality: np.ndarray
    force_quality: np.ndarray
    rest: np.ndarray                 # (2, 6) re-tare removed at onset and at release (N, N*m)
    touch: np.ndarray | None = None  # a curved phantom: where the tip touched (3,) lab, and the
    touch_normal: np.ndarray | None = None   # surface's outward normal there (3,)


def cut_presses(presses: list[Press], series: dict[str, np.ndarray], margin: int
                ) -> list[PressRecord]:
    """Each press with ``margin`` frames either side (never into a neighbouring press)."""
    out = []
    for k in range(len(presses)):
        local, lo, hi = cut_span(presses, k, len(series["time_ns"]), margin)
        out.append(PressRecord(local, **{key: v[lo:hi] for key, v in series.items()},
                               rest=np.zeros((2, 6))))
    return out


def cut_span(presses: list[Press], k: int, frames: int, margin: int) -> tuple[Press, int, int]:
    """Press ``k`` of a series of ``frames`` frames cut out with ``margin`` frames either side,
    never into a neighbouring press: the press on the cut's frames, and the cut [lo, hi)."""
    pr = presses[k]
    lo = max(pr.onset - margin, presses[k - 1].release if k else 0, 0)
    hi = min(pr.release + margin, presses[k + 1].onset if k + 1 < len(presses) else frames)
    return Press(pr.onset - lo, pr.release - lo, pr.peak - lo, pr.location, pr.repeat), lo, hi

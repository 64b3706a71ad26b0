"""Splitting a session into presses, naming each press's location and repeat, cutting them out.

A press runs from contact onset to release: the frames where the force magnitude stays above
a contact level (a few noise widths), in a run that rises above a detection level. Presses at
the same place on the phantom (tip within ``radius`` of a location's centre, measured in the
surface plane) share a location id; locations are numbered in the order they are first
pressed, repeats within each location. Each press is then cut out of the session's series with
a margin of unloaded frames on both sides (:func:`cut_presses`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core.runs import true_runs


@dataclass
class Press:
    """One press on the mocap frame index axis (``release`` is one past the last loaded frame)."""

    onset: int
    release: int
    peak: int
    location: int = -1
    repeat: int = -1


def segment_presses(
    force_magnitude: np.ndarray,
    rate_hz: float,
    detect_n: float,
    contact_n: float,
    min_duration_s: float = 0.2,
    merge_s: float = 0.05,
) -> tuple[list[Press], int]:
    """Complete presses in a force-magnitude series (NaN = unknown), and how many were cut off.

    Runs above ``contact_n`` closer than ``merge_s`` are merged (noise flicker at the contact
    level); a press is a merged run that peaks above ``detect_n`` and lasts ``min_duration_s``.
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
    for a, b in true_runs(f > contact_n):
        if spans and a - spans[-1][1] < merge_s * rate_hz:
            spans[-1][1] = b
        else:
            spans.append([a, b])
    presses, cut = [], 0
    for a, b in spans:
        if f[a:b].max() <= detect_n or (b - a) < min_duration_s * rate_hz:
            continue
        if a == 0 or b == len(f) or not known[a - 1 : b + 1].all():
            cut += 1
            continue
        presses.append(Press(a, b, a + int(np.argmax(f[a:b]))))
    return presses, cut


def assign_locations(
    centres: np.ndarray, radius: float = 0.010
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

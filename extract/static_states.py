"""Static states of lab presses: the surface at every force level of each loading phase.

For each press of a synced file, the state at level k x step (k = 0: the untouched surface just
before contact) is taken at the instant the force magnitude first reaches the level (linear
between frames). Points and force there are the value at that instant of a straight line fitted
over the frames within ``half_window_s`` of it, so per-frame marker noise is averaged down
instead of carried over; the line's slope gives the surface speed, which flags states that were
not quasi-static. k = 0 averages the frames of the ``rest_window_s`` before the force starts to
rise (:func:`contact_start`). A
level the press never reached is absent (never extrapolated).

Flagged, not guessed: a point with fewer than ``min_samples`` finite frames in the window is
invalid at that state (``valid`` False, NaN); a state whose tip is invalid is dropped (the tip
is the model's condition); a press with no loading phase is excluded. Both are counted.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from core.protocol import reaches, top_level
from extract.extract_params import ExtractParams


@dataclass
class PressSeries:
    """What extraction needs of one synced press."""

    time_s: np.ndarray         # (T,) mocap clock, s
    points: np.ndarray         # (T, P, 3) in the phantom frame, NaN where missing; last = tip
    force: np.ndarray          # (T,) magnitude, N
    onset: int                 # first loaded frame
    peak: int                  # frame of the peak force (end of loading)
    untrusted_force: bool = False   # sync flagged the force (saturated or over range)


@dataclass
class PressStates:
    """The states of one press, in level order."""

    points: np.ndarray         # (K, P, 3), NaN where invalid
    valid: np.ndarray          # (K, P) bool
    force: np.ndarray          # (K,) N
    step: np.ndarray           # (K,) level index
    speed: np.ndarray          # (K,) m/s, mean over the surface points
    time_s: np.ndarray         # (K,) the instant each state was read at (mocap clock)
    dropped: dict[str, int] = field(default_factory=dict)


def crossing_time(time_s: np.ndarray, force: np.ndarray, level: int, step_n: float
                  ) -> float | None:
    """First time ``force`` reaches level ``level`` (``level * step_n``, linear between
    frames), or None if never. It reaches it as :func:`~core.protocol.top_level` counts
    (:func:`~core.protocol.reaches`): a force short of it by rounding only does so at its
    frame, so a level counted as reached is always crossed."""
    hit = np.flatnonzero(reaches(force, level, step_n))
    if hit.size == 0:
        return None
    i = int(hit[0])
    if i == 0:
        return float(time_s[0])
    f0, f1 = force[i - 1], force[i]
    share = min(1.0, (level * step_n - f0) / (f1 - f0))
    return float(time_s[i - 1] + share * (time_s[i] - time_s[i - 1]))


def contact_start(force: np.ndarray, onset: int) -> int:
    """The frame where the force starts to rise towards ``onset``: sync's onset is where it
    passes a contact threshold, but the indenter touches the surface a little earlier. Walks
    back from onset while the force is above the rest's noise (median + 4 robust sd)."""
    rest = force[:onset]
    if rest.size < 5:
        return onset
    med = np.median(rest)
    thr = med + 4 * 1.4826 * np.median(np.abs(rest - med))
    i = onset
    while i > 0 and force[i - 1] > thr:
        i -= 1
    return i


def line_at(t: np.ndarray, values: np.ndarray, at: float, min_samples: int
            ) -> tuple[np.ndarray, np.ndarray]:
    """Value and slope at ``at`` of a straight line fitted to ``values`` (T, ...) over ``t``,
    per column, ignoring NaN; NaN where fewer than ``min_samples`` frames are finite, or where
    ``at`` lies farther beyond them than half their span: a line through a few noisy frames at
    one end of the window, carried to its middle, multiplies their noise (a marker seen only in
    the rest window's last 3 frames came out 18 mm off); within half the span a line's value
    errs at most sqrt(13 / n) times a frame's noise."""
    v = values.reshape(len(t), -1)
    ok = np.isfinite(v)
    n = ok.sum(axis=0)
    seen = np.where(ok, t[:, None], np.nan)
    with warnings.catch_warnings():           # a column never seen: no span, NaN below anyway
        warnings.simplefilter("ignore", RuntimeWarning)
        lo, hi = np.nanmin(seen, axis=0), np.nanmax(seen, axis=0)
    near = (at >= lo - (hi - lo) / 2) & (at <= hi + (hi - lo) / 2)
    dt = (t - at)[:, None] * ok
    y = np.where(ok, v, 0.0)
    mean_t, mean_y = dt.sum(0) / np.maximum(n, 1), y.sum(0) / np.maximum(n, 1)
    var = ((dt - mean_t) ** 2 * ok).sum(0)
    cov = ((dt - mean_t) * (y - mean_y) * ok).sum(0)
    slope = np.where(var > 0, cov / np.where(var > 0, var, 1.0), 0.0)
    value = mean_y - slope * mean_t
    enough = (n >= min_samples) & near
    shape = values.shape[1:]
    return (np.where(enough, value, np.nan).reshape(shape),
            np.where(enough, slope, np.nan).reshape(shape))


def press_states(press: PressSeries, p: ExtractParams, levels: bool = True) -> PressStates:
    """Every level the loading phase of ``press`` reached, as static states (none when
    ``levels`` is False: a press with no loading phase)."""
    t, f = press.time_s, press.force
    loading = slice(press.onset, press.peak + 1)
    rows: list[tuple[np.ndarray, float, int, float, float]] = []
    dropped = {"tip_missing": 0, "too_fast": 0}
    start = contact_start(f, press.onset)
    rest = (t >= t[start] - p.rest_window_s) & (t < t[start])
    top = top_level(np.nanmax(f[loading]), p.step_n) if levels else -1
    for k in range(top + 1):
        if k == 0:
            window, at = rest, float(t[rest].mean()) if rest.any() else float("nan")
        else:
            crossed = crossing_time(t[loading], f[loading], k, p.step_n)
            if crossed is None:     # cannot be: top_level and crossing_time share reaches()
                raise ValueError(f"level {k * p.step_n:g} N counted as reached, never crossed")
            at = crossed
            window = np.abs(t - at) <= p.half_window_s
        pts, vel = line_at(t[window], press.points[window], at, p.min_samples)
        force, _ = line_at(t[window], f[window], at, p.min_samples)
        surface_speed = np.linalg.norm(vel[:-1], axis=-1)
        speed = float(surface_speed[np.isfinite(surface_speed)].mean()) \
            if np.isfinite(surface_speed).any() else float("nan")
        if not np.isfinite(pts[-1]).all():
            dropped["tip_missing"] += 1
        elif p.max_speed is not None and speed > p.max_speed:
            dropped["too_fast"] += 1
        else:
            rows.append((pts, float(force), k, speed, at))
    n_pts = press.points.shape[1]
    pts = np.array([r[0] for r in rows]).reshape(len(rows), n_pts, 3)
    return PressStates(points=pts, valid=np.isfinite(pts).all(axis=-1),
                       force=np.array([r[1] for r in rows]), step=np.array([r[2] for r in rows]),
                       speed=np.array([r[3] for r in rows]), time_s=np.array([r[4] for r in rows]),
                       dropped=dropped)


def example_pairs(step: np.ndarray, sequence: np.ndarray, rng: np.random.Generator,
                  multi_per_sequence: int = 15) -> tuple[np.ndarray, np.ndarray]:
    """Single-step (t, t + 1) and multi-step pairs (d >= 2; up to ``multi_per_sequence``
    drawn per sequence without replacement, sorted) as (E, 2) state-index arrays."""
    single, multi = [], []
    for s in np.unique(sequence):
        idx = np.flatnonzero(sequence == s)
        idx = idx[np.argsort(step[idx], kind="stable")]
        st = step[idx]
        gap = st[None, :] - st[:, None]
        i, j = np.nonzero(gap == 1)
        single += list(zip(idx[i], idx[j], strict=True))
        i, j = np.nonzero(gap >= 2)
        if i.size:
            pick = np.sort(rng.choice(i.size, min(multi_per_sequence, i.size), replace=False))
            multi += list(zip(idx[i[pick]], idx[j[pick]], strict=True))
    as_pairs = lambda rows: np.array(rows, dtype=np.int64).reshape(-1, 2)  # noqa: E731
    return as_pairs(single), as_pairs(multi)

"""Clock alignment of the force logger to the mocap system: offset and drift.

Convention: an event at mocap time ``t_m`` (s) is stamped by the logger at
``t_f = offset_s + (1 + drift_ppm * 1e-6) * t_m``.

Two estimators, both ending in a straight-line fit of local offsets ``t_f - t_m`` against
``t_m`` whose intercept is the offset and whose slope is the drift, with their standard errors:

* trigger: rising edges of the logged TTL channel, located to sub-sample precision by linear
  interpolation at the half-amplitude crossing, matched to the mocap's trigger EVENT times;
* data: per press, the lag that best explains the tip depth as a smooth function of the force
  magnitude (a profile least-squares cross-correlation that is insensitive to the nonlinear
  force-depth law), scanned coarse to fine and refined to sub-sample by a parabola through the
  cost minimum; the whole-session lag that seeds it comes from an FFT cross-correlation of
  the contact state seen by each stream, over every lag at which the recordings overlap.

A data lock is then checked (:class:`Lock`): at least two presses, a plausible drift, a known
offset, and a force that rises with the tip's depth; :mod:`sync.clock_policy` refuses one that
fails.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

from core.errors import BadInput
from core.holes import JUMP, stamp_resolution_ns

MAX_DRIFT_PPM = 200.0      # a crystal oscillator drifts tens of ppm; hundreds is no lock
MAX_OFFSET_SD_S = 5e-3     # a data lock must pin the offset to a few mocap frames
MIN_RISE = 0.5             # rank correlation of force with depth over a press's loaded frames
MIN_RISING_SHARE = 0.8     # share of the presses in which the force must rise with the depth
MIN_PULSES = 3             # trigger edges and events the trigger clock needs
MIN_LOCK_PRESSES = 2       # one press matches any press of a similar shape: the intervals pin it
CONTENDER = 0.9            # a lag whose contact matches this nearly as well must fail its checks


@dataclass
class ClockFit:
    """A logger-vs-mocap clock model with its uncertainty."""

    offset_s: float
    drift_ppm: float
    offset_sd_s: float
    drift_sd_ppm: float
    rms_s: float          # RMS residual of the local offsets about the line
    n: int                # number of local offsets (pulses or presses) used
    method: str           # "trigger", "data", "shared" (one clock) or "none"

    def to_logger(self, t_mocap_s: np.ndarray) -> np.ndarray:
        """Logger time (s) of mocap times (s)."""
        return self.offset_s + (1.0 + self.drift_ppm * 1e-6) * np.asarray(t_mocap_s, float)

    def to_mocap(self, t_logger_s: np.ndarray) -> np.ndarray:
        """Mocap time (s) of logger times (s)."""
        return (np.asarray(t_logger_s, float) - self.offset_s) / (1.0 + self.drift_ppm * 1e-6)

    def as_dict(self) -> dict[str, float | int | str]:
        return asdict(self)


IDENTITY = ClockFit(0.0, 0.0, 0.0, 0.0, 0.0, 0, "none")


def fit_offsets(
    t_mocap_s: np.ndarray, offsets_s: np.ndarray, method: str, sd_s: np.ndarray | None = None
) -> ClockFit:
    """Straight line through local offsets ``t_f - t_m`` at mocap times ``t_m``.

    Weighted by ``1 / sd_s**2`` when given. Standard errors come from the weighted normal
    matrix, inflated by the residual scatter when that is larger than the weights claim. One
    offset alone gives zero drift with an infinite drift uncertainty.
    """
    x = np.asarray(t_mocap_s, float)
    y = np.asarray(offsets_s, float)
    n = len(x)
    if n == 0:
        raise ValueError("no offsets to fit")
    w = np.ones(n) if sd_s is None else 1.0 / np.maximum(np.asarray(sd_s, float), 1e-12) ** 2
    if n == 1:
        sd = float(np.sqrt(1.0 / w[0])) if sd_s is not None else float("inf")
        return ClockFit(float(y[0]), 0.0, sd, float("inf"), 0.0, 1, method)
    a = np.stack([np.ones(n), x], axis=1)
    normal = a.T @ (a * w[:, None])
    coef = np.linalg.solve(normal, a.T @ (w * y))
    resid = y - a @ coef
    rms = float(np.sqrt(np.mean(resid**2)))
    cov = np.linalg.inv(normal)
    if n > 2:
        chi2 = float(np.sum(w * resid**2) / (n - 2))
        cov = cov * (chi2 if sd_s is None else max(chi2, 1.0))
    elif sd_s is None:
        cov = cov * np.inf
    return ClockFit(
        offset_s=float(coef[0]), drift_ppm=float(coef[1] * 1e6),
        offset_sd_s=float(np.sqrt(cov[0, 0])), drift_sd_ppm=float(np.sqrt(cov[1, 1]) * 1e6),
        rms_s=rms, n=n, method=method,
    )


# --- trigger --------------------------------------------------------------------------------


def rising_edges(time_s: np.ndarray, signal: np.ndarray, threshold: float | None = None
                 ) -> np.ndarray:
    """Times (s) where ``signal`` rises through ``threshold`` (default: half-way between its
    lowest and highest values), linearly interpolated between the two samples around the
    crossing; none is read between two samples a hole parts (a step of two periods or more)."""
    t = np.asarray(time_s, float)
    x = np.asarray(signal, float)
    ok = np.isfinite(x)
    if ok.sum() < 2:
        return np.empty(0)
    lo, hi = np.min(x[ok]), np.max(x[ok])
    if threshold is None:
        if hi - lo <= 0:
            return np.empty(0)
        threshold = 0.5 * (lo + hi)
    below = np.where(ok, x < threshold, True)
    step = np.diff(t)
    adjacent = step < JUMP * np.median(step)
    i = np.flatnonzero(below[:-1] & ~below[1:] & ok[:-1] & ok[1:] & adjacent)
    frac = (threshold - x[i]) / (x[i + 1] - x[i])
    return t[i] + frac * (t[i + 1] - t[i])


def match_trigger(
    edges_logger_s: np.ndarray,
    events_mocap_s: np.ndarray,
    source: str | Path | None = None,
    prior: ClockFit | None = None,
    max_drift_ppm: float = MAX_DRIFT_PPM,
    min_pulses: int = MIN_PULSES,
    timing_sd_s: float = 0.0,
) -> ClockFit:
    """Clock from trigger pulses seen by both systems (logger edges, mocap EVENT times).

    Every (edge, event) pair proposes an offset; the proposal that explains the most pairs
    within a tolerance (the drift ``max_drift_ppm`` can build up over the session) wins, and it
    must explain at least half the pulses of the shorter list (a few missing on either side
    are fine; unrelated trains are refused). A periodic train makes
    proposals a period apart tie; ``prior`` (a data-driven estimate) then decides, and without
    it the tie is bad input. The matched pairs are fitted by :func:`fit_offsets`, each with
    at least ``timing_sd_s`` uncertainty (the rounding of both time stamps: with a square
    pulse and events written to the millisecond, a short session can show no scatter at all,
    and its drift is then far less certain than a perfect fit suggests).
    """
    e = np.sort(np.asarray(edges_logger_s, float))
    m = np.sort(np.asarray(events_mocap_s, float))
    if len(e) < min_pulses or len(m) < min_pulses:
        raise BadInput(source, f"trigger: {len(e)} pulse edges in the force log and {len(m)} "
                               f"trigger events in the mocap file; need at least {min_pulses} "
                               "of each")
    spacing = min(np.min(np.diff(e)), np.min(np.diff(m)))
    span = max(m[-1] - m[0], e[-1] - e[0])
    tol = min(0.4 * spacing, max(2e-3, max_drift_ppm * 1e-6 * span))
    diffs = np.sort((e[:, None] - m[None, :]).ravel())
    proposals = np.unique(np.round(diffs / (0.1 * tol))) * 0.1 * tol
    # tol < spacing / 2: an event has at most one edge within tol, and an edge at most one
    # event, so the pairs within tol of a proposal are its matches
    counts = (np.searchsorted(diffs, proposals + tol, side="right")
              - np.searchsorted(diffs, proposals - tol, side="left"))
    best = counts.max()
    if best < max(min_pulses, 0.5 * min(len(e), len(m))):
        raise BadInput(source, "trigger: the pulse edges of the force log and the mocap trigger "
                               "events do not match (the streams may not overlap in time)")
    top = proposals[counts >= best]
    groups = _cluster(top, 2 * tol)
    if len(groups) > 1:
        if prior is None:
            raise BadInput(source, "trigger: pulse train is periodic, the match is ambiguous "
                                   "by whole periods")
        centre = prior.offset_s + prior.drift_ppm * 1e-6 * np.median(m)
        groups.sort(key=lambda g: abs(np.mean(g) - centre))
    offset0 = float(np.mean(groups[0]))
    pairs_m, pairs_e = _pairs(e, m, lambda t: t + offset0, tol)
    fit = fit_offsets(pairs_m, pairs_e - pairs_m, "trigger")
    fine_tol = max(5 * fit.rms_s, 1e-3)
    pairs_m, pairs_e = _pairs(e, m, lambda t: fit.to_logger(t), min(tol, fine_tol))
    sd = np.full(len(pairs_m), timing_sd_s) if timing_sd_s > 0 else None
    fit = fit_offsets(pairs_m, pairs_e - pairs_m, "trigger", sd)
    if abs(fit.drift_ppm) > max_drift_ppm:
        raise BadInput(source, f"trigger: fitted clock drift {fit.drift_ppm:.0f} ppm is "
                               f"implausible (limit {max_drift_ppm:g} ppm)")
    return fit


def stamp_resolution_s(time_ns: np.ndarray) -> float:
    """The rounding of written time stamps (s): :func:`core.holes.stamp_resolution_ns`."""
    return stamp_resolution_ns(time_ns) * 1e-9


def _pairs(e: np.ndarray, m: np.ndarray, to_logger: Callable[[np.ndarray], np.ndarray],
           tol: float) -> tuple[np.ndarray, np.ndarray]:
    pred = to_logger(m)
    j = np.clip(np.searchsorted(e, pred), 1, len(e) - 1)
    j = np.where(np.abs(e[j - 1] - pred) < np.abs(e[j] - pred), j - 1, j)
    ok = np.abs(e[j] - pred) <= tol
    return m[ok], e[j[ok]]


def _cluster(values: np.ndarray, gap: float) -> list[np.ndarray]:
    v = np.sort(values)
    cuts = np.flatnonzero(np.diff(v) > gap) + 1
    return list(np.split(v, cuts))


# --- data-driven ----------------------------------------------------------------------------


def xcorr_curve(
    t_mocap_s: np.ndarray, signal_m: np.ndarray, signal_f_at: Callable[[np.ndarray], np.ndarray],
    t_logger_span: tuple[float, float], max_lag_s: float, rate_hz: float = 200.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Normalised cross-correlation of a mocap signal with a logger signal at every lag
    (logger minus mocap time, s) at which the two recordings overlap (and within
    ``max_lag_s``; inf: no other bound): the lags and the correlation, -inf where not
    admissible.

    FFT cross-correlation at ``rate_hz``, each stream on a grid from its own first stamp (so
    stamps from a logger's boot or from the epoch cost nothing: the lag adds the difference
    of the two start times); NaN samples count as the signal's mean. Every lag at which the
    recordings share a sample is scored, whatever their absolute stamps.
    """
    t0 = float(np.min(t_mocap_s))
    n_m = int(np.ceil((np.max(t_mocap_s) - t0) * rate_hz)) + 1
    grid_m = t0 + np.arange(n_m) / rate_hz
    a = np.interp(grid_m, t_mocap_s, np.asarray(signal_m, float))
    a = np.where(np.isfinite(a), a - np.nanmean(a), 0.0)
    lo, hi = t_logger_span
    n_f = int(np.floor((hi - lo) * rate_hz)) + 1
    b = np.asarray(signal_f_at(lo + np.arange(n_f) / rate_hz), float)
    b = np.where(np.isfinite(b), b - np.nanmean(b), 0.0)
    size = int(2 ** np.ceil(np.log2(n_m + n_f)))
    xc = np.fft.irfft(np.conj(np.fft.rfft(a, size)) * np.fft.rfft(b, size), size)
    shifts = np.arange(size)
    shifts = np.where(shifts < n_f, shifts, shifts - size)      # lag k: b[i + k] ~ a[i]
    overlap = (shifts > -n_m) & (shifts < n_f)
    lag_s = lo - t0 + shifts / rate_hz
    norm = float(np.sqrt((a @ a) * (b @ b)))
    xc = xc / norm if norm > 0 else np.zeros(size)
    xc = np.where(overlap & (np.abs(lag_s) <= max_lag_s), xc, -np.inf)
    order = np.argsort(lag_s)
    return lag_s[order], xc[order]


def curve_peaks(lags: np.ndarray, xc: np.ndarray, count: int, min_gap_s: float
                ) -> list[tuple[float, float]]:
    """The ``count`` highest local maxima of a correlation curve at least ``min_gap_s`` apart,
    best first, each as (parabola-refined lag, correlation)."""
    inner = np.isfinite(xc)
    if not inner.any():
        return []
    left = np.concatenate([[-np.inf], xc[:-1]])
    right = np.concatenate([xc[1:], [-np.inf]])
    cand = np.flatnonzero(inner & (xc >= left) & (xc >= right))
    cand = cand[np.argsort(-xc[cand], kind="stable")]
    step = float(lags[1] - lags[0]) if len(lags) > 1 else 0.0
    out: list[tuple[float, float]] = []
    for k in cand:
        if any(abs(lags[k] - lag) < min_gap_s for lag, _ in out):
            continue
        ok = 0 < k < len(xc) - 1 and np.isfinite(xc[k - 1] + xc[k + 1])
        frac = _parabola_vertex(xc[k - 1], xc[k], xc[k + 1]) if ok else 0.0
        out.append((float(lags[k] + frac * step), float(xc[k])))
        if len(out) == count:
            break
    return out


def contact_lags(
    t_mocap_s: np.ndarray, depth: np.ndarray, force_at: Callable[[np.ndarray], np.ndarray],
    t_logger_span: tuple[float, float], max_lag_s: float, force_level: float = 0.25,
    levels: int = 24, count: int = 4, min_gap_s: float = 0.5,
) -> list[tuple[float, float]]:
    """Whole-session lags (s) and their normalised correlations, best first, by matching
    contact: tip deeper than a level
    against force above ``force_level``; up to ``count`` peaks of the best level's
    correlation, ``min_gap_s`` apart (a lag a press cycle away can fit nearly as well).

    Raw depth is a poor partner for the force (the hand's moves between presses dominate it,
    and a lag of one press cycle can fit as well); the contact state is the same on/off pattern
    in both streams. The depth at which contact starts depends on the marker and tip geometry,
    so levels across the upper depth range are tried and the best-matching one kept. Every
    lag at which the recordings overlap is searched (within ``max_lag_s``; inf: unbounded).
    """
    finite = depth[np.isfinite(depth)]
    if finite.size == 0:
        raise ValueError("no depth")
    best: tuple[float, list[tuple[float, float]]] = (-np.inf, [])
    for level in np.unique(np.percentile(finite, np.linspace(30, 99, levels))):
        inside = np.where(np.isfinite(depth), (depth > level).astype(float), np.nan)
        lags, xc = xcorr_curve(t_mocap_s, inside,
                               lambda t: (force_at(t) > force_level).astype(float),
                               t_logger_span, max_lag_s)
        peaks = curve_peaks(lags, xc, count, min_gap_s)
        if peaks and peaks[0][1] > best[0]:
            best = (peaks[0][1], peaks)
    if not best[1]:
        raise ValueError("no admissible lag")
    return best[1]


def press_lag(
    t_mocap_s: np.ndarray, depth: np.ndarray, force_at: Callable[[np.ndarray], np.ndarray],
    lag0: float, half_width_s: float, step_s: float, degree: int = 3,
) -> tuple[float, float]:
    """Lag (s) near ``lag0`` minimising the misfit of depth = poly(force) over one press.

    ``t_mocap_s`` and ``depth`` are the press's loaded frames (chosen once, so every lag is
    scored on the same frames). The depth is the dependent variable because it carries most of
    the noise (the force is low-passed and far less noisy relative to its range). Returns the
    parabola-refined lag and its standard error from the cost curvature (as if the residuals
    were independent; :func:`clock_from_data` rescales by the scatter between presses).
    """
    lags = lag0 + np.arange(-half_width_s, half_width_s + 0.5 * step_s, step_s)
    cost = np.empty(len(lags))
    for i, lag in enumerate(lags):
        f = force_at(t_mocap_s + lag)
        if not np.isfinite(f).all():
            cost[i] = np.inf
            continue
        g = (f - f.mean()) / max(f.std(), 1e-12)
        q, _ = np.linalg.qr(np.vander(g, degree + 1))
        cost[i] = float(np.sum((depth - q @ (q.T @ depth)) ** 2))
    k = int(np.argmin(cost))
    if k == 0 or k == len(lags) - 1 or not np.isfinite(cost[k - 1 : k + 2]).all():
        return float(lags[k]), float("inf")
    frac = _parabola_vertex(cost[k - 1], cost[k], cost[k + 1])
    lag = float(lags[k] + frac * step_s)
    curv = (cost[k - 1] - 2 * cost[k] + cost[k + 1]) / step_s**2
    dof = max(len(depth) - degree - 2, 1)
    sd = float(np.sqrt(2.0 * cost[k] / dof / curv)) if curv > 0 else float("inf")
    return lag, sd


def clock_from_data(
    presses: Sequence[tuple[np.ndarray, np.ndarray]],
    force_at: Callable[[np.ndarray], np.ndarray],
    lag0: float,
    source: str | Path | None = None,
    search_s: float = 0.05,
    max_walk: int = 10,
) -> ClockFit:
    """Clock from per-press lags: ``presses`` are (mocap times, tip depth) of loaded frames.

    Each press is scanned over ``lag0 +- search_s`` at 1 ms (while its best lag lies on its
    edge, the scan moves on to the next window beyond that edge, up to ``max_walk`` times: the
    contact-state seed can be off by a few tenths of a second when presses are slow), then
    +-2 ms at 0.1 ms; the local lags are fitted by :func:`fit_offsets` (weighted by their
    standard errors).
    """
    times, lags, sds = [], [], []
    for t, d in presses:
        ok = np.isfinite(d)
        if ok.sum() < 20:
            continue
        t, d = t[ok], d[ok]
        centre = lag0
        for _ in range(max_walk + 1):
            lag, sd = press_lag(t, d, force_at, centre, search_s, 1e-3)
            if np.isfinite(sd) or lag == centre:
                break
            centre = lag + np.sign(lag - centre) * (search_s - 1e-3)   # next window beyond
        lag, sd = press_lag(t, d, force_at, lag, 2e-3, 1e-4)
        if np.isfinite(sd):
            times.append(float(np.mean(t)))
            lags.append(lag)
            sds.append(sd)
    if not lags:
        raise BadInput(source, "clock: no press has enough tracked tip frames to align the "
                               "force to the motion")
    return fit_offsets(np.array(times), np.array(lags), "data", np.array(sds))


# --- is the data lock to be trusted? ------------------------------------------------------

@dataclass
class Lock:
    """A data-driven clock and the figures that say whether it can be trusted."""

    fit: ClockFit
    rising: int                # presses in which the force rises with the tip's depth
    checked: int               # presses with enough tracked frames to check
    correlation: float         # force against depth over the whole session

    def problems(self, min_correlation: float) -> list[str]:
        """What is wrong with this lock, in words with the figures (empty: trusted).

        A wrong lag shows in every figure: presses matched to the force of another press give
        local lags that disagree (a large offset uncertainty, a drift of hundreds of ppm, a
        real crystal drifts tens), and a force that does not rise with the depth. A lock on
        one press cannot be told from a lock on a similar press: only the intervals between
        presses pin the offset.
        """
        f, out = self.fit, []
        if f.n < MIN_LOCK_PRESSES:
            out.append(f"it rests on {f.n} press (need {MIN_LOCK_PRESSES}: one press matches any "
                       "press of a similar shape)")
        if abs(f.drift_ppm) > MAX_DRIFT_PPM or (f.n > 1 and f.drift_sd_ppm > MAX_DRIFT_PPM):
            out.append(f"drift {f.drift_ppm:.0f} +- {f.drift_sd_ppm:.0f} ppm (a crystal drifts "
                       f"tens of ppm; limit {MAX_DRIFT_PPM:g})")
        if not f.offset_sd_s <= MAX_OFFSET_SD_S:
            out.append(f"offset uncertain by {f.offset_sd_s * 1e3:.1f} ms (limit "
                       f"{MAX_OFFSET_SD_S * 1e3:g} ms)")
        if self.checked == 0 or self.rising < MIN_RISING_SHARE * self.checked:
            out.append(f"force rises with the tip's depth in {self.rising} of {self.checked} "
                       f"presses (need {MIN_RISING_SHARE:.0%})")
        if not self.correlation >= min_correlation:
            out.append(f"force-depth correlation {self.correlation:.2f} (need "
                       f"{min_correlation:g})")
        return out


def rank_correlation(x: np.ndarray, y: np.ndarray) -> float:
    """Spearman's rank correlation of two series (ties take their mean rank; NaN pairs left
    out); NaN with fewer than 3 pairs or a constant series."""
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 3 or np.ptp(x[ok]) == 0 or np.ptp(y[ok]) == 0:
        return float("nan")
    return float(spearmanr(x[ok], y[ok]).statistic)


def rising_presses(windows: Sequence[tuple[np.ndarray, np.ndarray]], min_frames: int = 20
                   ) -> tuple[int, int]:
    """Of the (force, depth) windows of loaded frames with ``min_frames`` tracked, how many
    have the force rising with the depth (rank correlation at least :data:`MIN_RISE`), and
    how many were checked."""
    rho = [rank_correlation(f, d) for f, d in windows
           if (np.isfinite(f) & np.isfinite(d)).sum() >= min_frames]
    return sum(1 for r in rho if r >= MIN_RISE), len(rho)


def _parabola_vertex(ym: float, y0: float, yp: float) -> float:
    """Offset (in steps, clipped to +-1) of the vertex of the parabola through 3 equally
    spaced points (a maximum or a minimum)."""
    den = ym - 2 * y0 + yp
    if den == 0:
        return 0.0
    return float(np.clip(0.5 * (ym - yp) / den, -1.0, 1.0))

"""Holes in a uniformly sampled stream: stretches of samples that were never recorded.

A DAQ buffer overrun, a Speedgoat overrun, a QTM real-time client that reconnects, a recording
paused and resumed: the samples of the gap are gone, and the stream's own clock (its time
stamps, or its sample numbers) jumps over them. A hole is a jump of at least two sampling
periods (one sample or more lost, or a pause of that length); a step that is neither about one
period nor such a jump is jitter, and a stream with jitter is bad input (a resampler needs a
uniform grid between holes). :func:`find_holes` tells the two apart; the stretches between
holes are uniform.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.errors import BadInput

JITTER = 0.1     # a step within this share of the period of it is one period
PRINT_CAP = 0.45  # the printed stamps' rounding widens that to at most this share: beyond it a
#                   whole lost sample could pass for a step
JUMP = 2 - JITTER  # a step this many periods long or more (less the rounding) is a hole


@dataclass(frozen=True)
class Hole:
    """A jump in a stream's clock: the samples before it end at ``index - 1``, ``index`` is
    the first sample after it."""

    index: int          # the first sample after the hole
    start_ns: int       # time of the last sample before it
    stop_ns: int        # time of the first sample after it
    period_ns: float    # the stream's sampling period

    @property
    def lost(self) -> int:
        """Samples missing in the hole (a pause that is no whole number of periods rounds)."""
        return max(int(round((self.stop_ns - self.start_ns) / self.period_ns)) - 1, 1)

    @property
    def whole(self) -> bool:
        """Whether the jump is a whole number of periods (samples lost, the clock running
        on), not a pause of another length."""
        periods = (self.stop_ns - self.start_ns) / self.period_ns
        return abs(periods - round(periods)) <= JITTER

    @property
    def length_s(self) -> float:
        """How long the stream recorded nothing: the jump less one period (s)."""
        return (self.stop_ns - self.start_ns - self.period_ns) * 1e-9

    def describe(self, what: str, unit: str = "samples") -> str:
        """``"0.400 s of <what> lost (200 <unit>) after 10.000 s"`` (the stream's own time,
        as its file writes it), for a warning line."""
        return (f"{self.length_s:.3f} s of {what} lost ({self.lost} "
                f"{unit[:-1] if self.lost == 1 else unit}) after "
                f"{self.start_ns * 1e-9:.3f} s")


@dataclass(frozen=True)
class Timing:
    """A stream's sampling period and the holes in its clock."""

    period_ns: float
    holes: tuple[Hole, ...] = ()

    def stretches(self, samples: int) -> list[tuple[int, int]]:
        """The uniform runs of samples between the holes, as [start, stop) index pairs."""
        cuts = [0, *(h.index for h in self.holes), samples]
        return list(zip(cuts[:-1], cuts[1:], strict=True))


def find_holes(time_ns: np.ndarray, source: str | Path | None, what: str = "samples",
               where: Callable[[int], str] | None = None) -> Timing:
    """The period and the holes of increasing times ``time_ns``.

    A step within :data:`JITTER` of the period, plus the stamps' own rounding
    (:func:`rounding_ns`: a time column written to the millisecond), is one period
    (the tolerance at most :data:`PRINT_CAP` of it); a longer step of at least two periods
    less that tolerance is a hole; any other step is jitter, refused in one line naming
    ``source`` and the sample (``where(i)`` names sample ``i`` in the file's own terms, "line
    12"). The period is the mean of the steps that are one period (their median first picks
    them), so a hole of thousands of samples at 300 Hz counts them exactly.
    """
    t = np.asarray(time_ns, np.int64)
    steps = np.diff(t).astype(np.float64)
    if steps.size == 0:
        return Timing(float("nan"))
    median = float(np.median(steps))
    tol = min(JITTER * median + rounding_ns(t, steps, median), PRINT_CAP * median)
    normal = np.abs(steps - median) <= tol
    jump = ~normal & (steps >= 2 * median - tol)
    jitter = np.flatnonzero(~normal & ~jump)
    if jitter.size:
        i = int(jitter[0]) + 1
        raise BadInput(source, f"{what} are not evenly spaced: a step of "
                               f"{steps[i - 1] * 1e-6:.3f} ms where the period is "
                               f"{median * 1e-6:.3f} ms (jitter, not a hole of lost samples)",
                       where=where(i) if where is not None else f"sample {i}")
    period = float(steps[normal].mean())
    holes = tuple(Hole(int(i) + 1, int(t[i]), int(t[i + 1]), period)
                  for i in np.flatnonzero(jump))
    return Timing(period, holes)


def rounding_ns(time_ns: np.ndarray, steps: np.ndarray, median: float) -> float:
    """How far a step may be off for the stamps' rounding alone: their resolution
    (:func:`stamp_resolution_ns`) where the period is no whole number of it (300 Hz written to
    the millisecond: steps of 3 and 4 ms), else 0 (exact stamps round to themselves)."""
    res = stamp_resolution_ns(time_ns)
    near = steps[np.abs(steps - median) <= PRINT_CAP * median]
    ratio = float(near.mean()) / res if near.size else 0.0
    return 0.0 if abs(ratio - round(ratio)) < 0.05 else res


def stamp_resolution_ns(time_ns: np.ndarray) -> float:
    """The coarsest power-of-ten step (1 ns .. 1 s) that every stamp is a multiple of: the
    rounding of times written with a fixed number of decimals (a QTM Time column to the
    millisecond)."""
    t = np.asarray(time_ns, np.int64)
    step = 1
    while step < 10**9 and t.size and np.all(t % (step * 10) == 0):
        step *= 10
    return float(step)


GRID_SHARE = 0.1     # a written time may lie this share of a sample off its rate's grid


def counted_numbers(numbers: np.ndarray, source: str | Path | None,
                    what: str = "SAMPLE") -> np.ndarray:
    """A sample-number column (QTM's SAMPLE) as int64 numbers from 0: whole and increasing;
    a number that skips marks a hole. Else bad input naming ``what``."""
    n = np.asarray(numbers, float)
    bad = np.flatnonzero(~np.isfinite(n) | (n != np.round(n)))
    if bad.size:
        raise BadInput(source, f"{what} {n[bad[0]]:g} is no sample number",
                       where=f"sample {int(bad[0]) + 1}")
    back = np.flatnonzero(np.diff(n) <= 0)
    if back.size:
        raise BadInput(source, f"{what} does not increase ({n[back[0] + 1]:g} after "
                               f"{n[back[0]]:g})", where=f"sample {int(back[0]) + 2}")
    return (n - n[0]).astype(np.int64) if n.size else n.astype(np.int64)


def grid_numbers(time_s: np.ndarray, rate_hz: float, source: str | Path | None,
                 what: str = "TIME", print_s: float = 0.0) -> np.ndarray:
    """The sample numbers (int64, 0 at the first) of times ``time_s`` written on the grid of
    ``rate_hz`` (a QTM export's TIME column, rounded to ``print_s``): numbers that skip are
    the samples of a hole. A time off the grid, or a column that runs at another rate (most
    steps not one sample), contradicts the rate: bad input naming ``what``."""
    t = np.asarray(time_s, float)
    if t.size == 0:
        return np.zeros(0, np.int64)
    at = (t - t[0]) * rate_hz
    numbers = np.rint(at).astype(np.int64)
    off = np.abs(at - numbers)
    worst = int(np.argmax(off))
    if off[worst] > GRID_SHARE + print_s * rate_hz:
        raise BadInput(source, f"{what} departs from the rate {rate_hz:g} Hz by "
                               f"{off[worst] / rate_hz * 1e3:.3f} ms at sample {worst + 1}: "
                               "the header contradicts the data")
    steps = np.diff(numbers)
    if steps.size and (steps.min() < 1 or np.median(steps) != 1):
        rate = rate_hz / float(np.median(steps)) if steps.min() >= 1 else float("nan")
        raise BadInput(source, f"{what} runs at {rate:.4g} Hz, not at the stated "
                               f"{rate_hz:g} Hz: the header contradicts the data")
    return numbers

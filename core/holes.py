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
    def length_s(self) -> float:
        """How long the stream recorded nothing: the jump less one period (s)."""
        return (self.stop_ns - self.start_ns - self.period_ns) * 1e-9

    def describe(self, what: str) -> str:
        """``"0.400 s of <what> lost (200 samples) after 10.000 s"`` (the stream's own time,
        as its file writes it), for a warning line."""
        return (f"{self.length_s:.3f} s of {what} lost ({self.lost} "
                f"{'sample' if self.lost == 1 else 'samples'}) after "
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
               resolution_ns: float = 0.0, where: Callable[[int], str] | None = None
               ) -> Timing:
    """The period (the median step) and the holes of increasing times ``time_ns``.

    A step within :data:`JITTER` of the period (plus ``resolution_ns``, how finely the times
    were written) is one period; any longer step of at least two periods less that tolerance
    is a hole; any other step is jitter, refused in one line naming ``source`` and the sample
    (``where(i)`` names sample ``i`` in the file's own terms, "line 12").
    """
    t = np.asarray(time_ns, np.int64)
    steps = np.diff(t).astype(np.float64)
    if steps.size == 0:
        return Timing(float("nan"))
    period = float(np.median(steps))
    tol = JITTER * period + resolution_ns
    normal = np.abs(steps - period) <= tol
    jump = ~normal & (steps >= 2 * period - tol)
    jitter = np.flatnonzero(~normal & ~jump)
    if jitter.size:
        i = int(jitter[0]) + 1
        raise BadInput(source, f"{what} are not uniformly sampled: a step of "
                               f"{steps[i - 1] * 1e-6:.3f} ms where the period is "
                               f"{period * 1e-6:.3f} ms (jitter, not a hole of lost samples)",
                       where=where(i) if where is not None else f"sample {i}")
    holes = tuple(Hole(int(i) + 1, int(t[i]), int(t[i + 1]), period)
                  for i in np.flatnonzero(jump))
    return Timing(period, holes)


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

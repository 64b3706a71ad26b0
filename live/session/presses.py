"""Presses as they happen.

Sync's rule (:class:`sync.presses.PressRule`) applied sample by sample to the tared force
magnitude: a contact begins above the contact level and ends once it has stayed below for
longer than the rule bridges (noise flicker at the contact level is one contact); it is a
press when the rule calls it one, its duration counted in samples from its first above contact
to its last, both counted, as sync counts its frames from onset to release. Where it landed,
its location and its states follow once the session after it has arrived
(:mod:`live.session.states`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sync.presses import PressRule


@dataclass
class PressDone:
    """A press just ended: its number, peak (N), the times it spans and of its peak (ns)."""

    number: int
    peak_n: float
    start_ns: int
    end_ns: int
    peak_ns: int


@dataclass
class PressTracker:
    """Contacts and presses of one session, sample by sample, at ``rate_hz`` samples a
    second."""

    rate_hz: float
    rule: PressRule
    presses: int = 0
    _start: int | None = None       # the contact's first sample time (ns), None: no contact
    _below: int = 0                 # samples below contact since it last was above
    _last_above: int = 0
    _peak: float = 0.0
    _peak_t: int = 0

    @property
    def in_contact(self) -> bool:
        """Whether a contact goes on."""
        return self._start is not None

    def add(self, times_ns: np.ndarray, magnitude: np.ndarray) -> list[PressDone]:
        """A frame's samples: the presses that ended."""
        done = []
        for t, f in zip(times_ns.tolist(), magnitude.tolist(), strict=True):
            if self.rule.touching(f):
                if self._start is None:
                    self._start, self._peak = t, 0.0
                self._below, self._last_above = 0, t
                if f > self._peak:
                    self._peak, self._peak_t = f, t
            elif self._start is not None:
                self._below += 1
                if not self.rule.bridges(self._below, self.rate_hz):
                    done += self._end(self._start)
        return done

    def _end(self, start: int) -> list[PressDone]:
        """The contact that began at ``start`` (ns) is over: the press it was, if any."""
        end, peak = self._last_above, self._peak
        self._start = None
        samples = round((end - start) * 1e-9 * self.rate_hz) + 1
        if not self.rule.is_press(peak, samples, self.rate_hz):
            return []
        self.presses += 1
        return [PressDone(self.presses, peak, start, end, self._peak_t)]

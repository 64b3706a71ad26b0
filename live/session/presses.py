"""Presses as they happen.

Sync's rules (:func:`sync.presses.segment_presses`) applied sample by sample to the tared force
magnitude: a contact begins above ``contact_n`` and ends once it has stayed below for
``merge_s`` (noise flicker at the contact level is one contact); it is a press when it peaked
above ``detect_n`` and lasted ``min_duration_s``. Where it landed, its location and its states
follow once the session after it has arrived (:mod:`live.session.states`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
    """Contacts and presses of one session, sample by sample."""

    rate_hz: float
    detect_n: float
    contact_n: float
    min_duration_s: float = 0.2
    merge_s: float = 0.05
    presses: int = 0
    _start: int | None = None       # the contact's first sample time (ns), None: no contact
    _below: int = 0                 # samples below contact since it last was above
    _last_above: int = 0
    _peak: float = 0.0
    _peak_t: int = 0

    @property
    def in_contact(self) -> bool:
        return self._start is not None

    def add(self, times_ns: np.ndarray, magnitude: np.ndarray) -> list[PressDone]:
        """A frame's samples: the presses that ended."""
        done = []
        for t, f in zip(times_ns.tolist(), magnitude.tolist(), strict=True):
            if f > self.contact_n:
                if self._start is None:
                    self._start, self._peak = t, 0.0
                self._below, self._last_above = 0, t
                if f > self._peak:
                    self._peak, self._peak_t = f, t
            elif self._start is not None:
                self._below += 1
                if self._below >= self.merge_s * self.rate_hz:
                    done += self._end()
        return done

    def _end(self) -> list[PressDone]:
        start, end, peak = self._start, self._last_above, self._peak
        self._start = None
        if peak <= self.detect_n or (end - start) * 1e-9 < self.min_duration_s:
            return []
        self.presses += 1
        return [PressDone(self.presses, peak, start, end, self._peak_t)]

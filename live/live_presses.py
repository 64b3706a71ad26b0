"""Presses as they happen, and where the session still needs them.

Sync's rules (:func:`sync.presses.segment_presses`) applied sample by sample to the tared force
magnitude: a contact begins above ``contact_n`` and ends once it has stayed below for
``merge_s`` (noise flicker at the contact level is one contact); it is a press when it peaked
above ``detect_n`` and lasted ``min_duration_s``. Each press is placed by the tip at its peak
(the mocap's frame) and joins the location whose first press lies within ``radius_m`` of it, as
sync assigns locations. The coverage is, per location, the presses and the highest force level
reached (in steps of :data:`core.protocol.STEP_N`): what a person needs to see to press again
where states are missing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from core.protocol import STEP_N


@dataclass
class Location:
    """Where presses landed: the first press's tip (x, y, z, m), the presses, the peak (N)."""

    tip: np.ndarray
    presses: int = 0
    peak_n: float = 0.0

    @property
    def top_level(self) -> float:
        """The highest force level (N, a multiple of the step) any press here reached."""
        return math.floor(self.peak_n / STEP_N + 1e-9) * STEP_N


@dataclass
class PressDone:
    """A press just ended: its number, location, peak (N) and the times it spans (ns)."""

    number: int
    location: int
    peak_n: float
    start_ns: int
    end_ns: int


@dataclass
class PressTracker:
    """Contacts and presses of one session, sample by sample."""

    rate_hz: float
    detect_n: float
    contact_n: float
    radius_m: float
    min_duration_s: float = 0.2
    merge_s: float = 0.05
    locations: list[Location] = field(default_factory=list)
    presses: int = 0
    _start: int | None = None       # the contact's first sample time (ns), None: no contact
    _below: int = 0                 # samples below contact since it last was above
    _last_above: int = 0
    _peak: float = 0.0
    peak_tip: np.ndarray | None = None

    @property
    def in_contact(self) -> bool:
        return self._start is not None

    def add(self, times_ns: np.ndarray, magnitude: np.ndarray) -> tuple[bool, list[PressDone]]:
        """A frame's samples: whether one is a new highest of the current contact (its tip
        is then wanted: :meth:`place`), and the presses that ended."""
        done, new_peak = [], False
        for t, f in zip(times_ns.tolist(), magnitude.tolist(), strict=True):
            if f > self.contact_n:
                if self._start is None:
                    self._start, self._peak, self.peak_tip = t, 0.0, None
                self._below, self._last_above = 0, t
                if f > self._peak:
                    self._peak, new_peak = f, True
            elif self._start is not None:
                self._below += 1
                if self._below >= self.merge_s * self.rate_hz:
                    done += self._end()
        return new_peak, done

    def place(self, tip: np.ndarray) -> None:
        """The tip at the current contact's highest force so far."""
        if np.isfinite(tip).all():
            self.peak_tip = tip

    def _end(self) -> list[PressDone]:
        start, end, peak = self._start, self._last_above, self._peak
        self._start = None
        if peak <= self.detect_n or (end - start) * 1e-9 < self.min_duration_s or \
                self.peak_tip is None:
            return []
        where = self._location(self.peak_tip)
        loc = self.locations[where]
        loc.presses += 1
        loc.peak_n = max(loc.peak_n, peak)
        self.presses += 1
        return [PressDone(self.presses, where, peak, start, end)]

    def _location(self, tip: np.ndarray) -> int:
        for i, loc in enumerate(self.locations):
            if np.linalg.norm(loc.tip[:2] - tip[:2]) <= self.radius_m:
                return i
        self.locations.append(Location(tip.copy()))
        return len(self.locations) - 1

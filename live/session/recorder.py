"""Frames as they arrive, put on the mocap's clock and into the journal a second at a time.

A frame's time is its number since the first frame over the marker rate, and a force sample's
(a board's, a plate's) its number since the first sample over the device's rate: time 0 at the
first frame, as ingest times an analog or force-plate export, so the journal turns into the
same streams an export would give. Frames QTM numbered but never sent (a gap in the numbers)
are counted, not invented.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from core.errors import BadInput
from live.protocol.client import Frame
from live.session.journal import FORCE, MARKERS, Journal, Samples
from live.session.layout import LiveLayout

FLUSH_S = 1.0                 # seconds of samples per journal block


@dataclass
class Counts:
    """What arrived: frames, frame numbers skipped, force samples, and the frames a server
    sent again after a reconnection (recorded once)."""

    frames: int = 0
    skipped: int = 0
    samples: int = 0
    resent: int = 0


@dataclass
class Recorder:
    """Puts each :class:`Frame` on the clock and into the journal (``journal`` may be None:
    then nothing is written, as for a latency benchmark's dry run)."""

    layout: LiveLayout
    journal: Journal | None
    counts: Counts = field(default_factory=Counts)
    first_number: int | None = None
    first_sample: int | None = None
    last_number: int | None = None
    resuming: bool = False          # after a reconnection: frames up to the last are had
    _pending: dict[str, Samples] = field(default_factory=lambda: {MARKERS: Samples(),
                                                                 FORCE: Samples()})

    def add(self, frame: Frame) -> tuple[int, np.ndarray | None, np.ndarray | None] | None:
        """Record one frame; returns its time (ns) and the force samples' times and values
        (None where it carried none); None for a frame recorded before a reconnection."""
        if self.resuming:
            if self.last_number is None:    # a reconnection follows a first frame
                raise ValueError("resuming a stream that recorded no frame")
            if frame.number <= self.last_number:
                self.counts.resent += 1
                return None
            self.resuming = False
        self._check(frame)
        if self.last_number is None:
            self.first_number = frame.number
        elif frame.number > self.last_number + 1:
            self.counts.skipped += frame.number - self.last_number - 1
        self.last_number = frame.number
        t = self._frame_time(frame.number)
        self._pending[MARKERS].add(np.array([t], np.int64), frame.markers.reshape(1, -1))
        self.counts.frames += 1
        times = None if frame.force is None else self._samples(frame, frame.force)
        if self._pending[MARKERS].samples >= FLUSH_S * self.layout.rate_hz:
            self.flush()
        return t, times, frame.force

    def _samples(self, frame: Frame, force: np.ndarray) -> np.ndarray:
        """Record a frame's force samples (n, C); their times (ns)."""
        if frame.first_sample is None:
            raise ValueError(f"frame {frame.number}: force samples without their number")
        if self.first_sample is None:
            self.first_sample = frame.first_sample
        n = len(force)
        numbers = frame.first_sample - self.first_sample + np.arange(n)
        times = np.round(numbers * (1e9 / self.layout.device.rate_hz)).astype(np.int64)
        self._pending[FORCE].add(times, force)
        self.counts.samples += n
        return times

    def flush(self) -> None:
        """Write what is pending to the journal (each stream as one block)."""
        for topic, stream in self._pending.items():
            if stream.samples and self.journal is not None:
                k = stream.values[0].shape[1]
                self.journal.append(topic, *stream.arrays(k))
            self._pending[topic] = Samples()

    @property
    def last_time_ns(self) -> int:
        """The time of the last frame recorded (0 before any)."""
        return 0 if self.last_number is None else self._frame_time(self.last_number)

    def _frame_time(self, number: int) -> int:
        """Frame ``number``'s time (ns) since the first frame."""
        if self.first_number is None:
            raise ValueError("no frame recorded yet: no clock")
        return int(round((number - self.first_number) * (1e9 / self.layout.rate_hz)))

    def _check(self, frame: Frame) -> None:
        """A frame must carry every label QTM announced, in increasing frame numbers."""
        if frame.markers.shape[0] != len(self.layout.labels):
            raise BadInput(self.layout.source, f"frame {frame.number} carries "
                                               f"{frame.markers.shape[0]} markers, its "
                                               f"parameters name {len(self.layout.labels)}")
        if self.last_number is not None and frame.number <= self.last_number:
            raise BadInput(self.layout.source, f"frame {frame.number} after frame "
                                               f"{self.last_number}: frame numbers must "
                                               "increase")
        d = self.layout.device
        if frame.force is not None and frame.force.shape[1] != len(d.labels):
            raise BadInput(self.layout.source, f"frame {frame.number}: the {d.what} sends "
                                               f"{frame.force.shape[1]} channels, its "
                                               f"parameters name {len(d.labels)}")

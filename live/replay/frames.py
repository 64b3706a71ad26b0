"""A replayed frame as a QTM data packet (layouts: :mod:`live.protocol.packets`).

Frame ``i`` of the source goes out as frame number ``i + 1`` (QTM numbers a file's frames from
1) with its time in microseconds. The 3D component holds every label's marker, NaN when lost;
the 3D-without-labels component only the markers seen, each with its label's place (from 1)
as its id, where a real QTM numbers unidentified trajectories itself; the analog component the
force's samples where an analog device carries them (else no device), the force component
where a force plate does (else no plate): each sample numbered by its index in the session's
force stream.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from live.protocol.packets import (
    AnalogBlock,
    Component,
    ForceBlock,
    encode_3d,
    encode_3d_no_labels,
    encode_analog,
    encode_data,
    encode_force,
)
from live.replay.parameters import DEVICE_ID, PLATE_ID
from live.replay.source import ReplaySource

FIRST_FRAME = 1          # the number of a recording's first frame


def frame_packet(source: ReplaySource, frame: int, components: Sequence[Component],
                 samples_from: int | None = None) -> bytes:
    """The data packet of frame ``frame`` with ``components``; its force samples (analog or
    force component) are those of frames ``samples_from`` to ``frame`` (default: the frame's
    own), so that a stream of every n-th frame still carries every sample."""
    start = frame if samples_from is None else samples_from
    parts = [_ENCODERS[c](source, frame, start) for c in components]
    return encode_data(source.timestamp_us(frame), frame + FIRST_FRAME, parts)


def _three_d(source: ReplaySource, frame: int, start: int) -> bytes:
    return encode_3d(source.markers_mm[frame])


def _three_d_no_labels(source: ReplaySource, frame: int, start: int) -> bytes:
    xyz = source.markers_mm[frame]
    seen = ~np.isnan(xyz).any(axis=1)
    return encode_3d_no_labels(xyz[seen], np.flatnonzero(seen) + 1)


def _analog(source: ReplaySource, frame: int, start: int) -> bytes:
    got = _samples(source, frame, start, Component.ANALOG)
    return encode_analog([] if got is None else [AnalogBlock(DEVICE_ID, *got)])


def _force(source: ReplaySource, frame: int, start: int) -> bytes:
    got = _samples(source, frame, start, Component.FORCE)
    return encode_force([] if got is None else [ForceBlock(PLATE_ID, *got)])


def _samples(source: ReplaySource, frame: int, start: int, component: Component
             ) -> tuple[int, np.ndarray] | None:
    """The force's samples of frames ``start`` to ``frame`` (the first one's number, the
    values) for ``component``'s one block (device or plate), where that component carries
    the force; else None."""
    if source.force.component != component:
        return None
    return source.force.samples(start, frame + 1)


_ENCODERS: dict[Component, Callable[[ReplaySource, int, int], bytes]] = {
    Component.THREE_D: _three_d, Component.THREE_D_NO_LABELS: _three_d_no_labels,
    Component.ANALOG: _analog, Component.FORCE: _force}

"""A twin session's frames as ``pipeline live`` receives them, without a connection: each frame
encoded by the replay's server code (:func:`live.replay.frames.frame_packet`), decoded by the
client's (:func:`live.protocol.client.decode_frame`) and put on the clock by the recorder, and
the layout and tip a live session builds from QTM's parameters document. For tests of the live
session's per-frame work (:mod:`live.session.monitor`) frame by frame."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from data_schema.session import SessionConfig, read_session
from live.protocol.client import Frame, decode_frame
from live.protocol.packets import Component, PacketReader
from live.protocol.parameters import parse_parameters
from live.replay.frames import frame_packet
from live.replay.parameters import DEVICE_ID, parameters_xml
from live.replay.source import ReplaySource, read_replay_source
from live.session.calibration import TipModel, tip_model
from live.session.layout import LiveLayout, live_layout
from live.session.recorder import Recorder
from sync.sync_params import SyncParams

SECTIONS = ("general", "3d", "analog")
VERSION = "1.28"


@dataclass
class LiveInputs:
    """What a live session of the twin's ``folder`` works from."""

    cfg: SessionConfig
    source: ReplaySource
    layout: LiveLayout
    tip: TipModel


def live_inputs(folder: Path) -> LiveInputs:
    """The session's config, what the replay serves, the layout QTM's parameters give and the
    tip from the session's pivot recording (a twin session whose force QTM's board samples)."""
    cfg = read_session(folder)
    source = read_replay_source(folder)
    params = parse_parameters(parameters_xml(source, SECTIONS, VERSION), "replay")
    layout = live_layout(params, cfg)
    return LiveInputs(cfg, source, layout, tip_model(cfg, layout, None, SyncParams()))


def frames(inputs: LiveInputs) -> Iterator[tuple[Frame, int, np.ndarray | None]]:
    """Every frame, as it arrives: the frame, its time (ns) and its force samples' times."""
    recorder = Recorder(inputs.layout, None)
    components = (Component.THREE_D, Component.ANALOG)
    reader = PacketReader()
    for i in range(inputs.source.frames):
        (packet,) = reader.feed(frame_packet(inputs.source, i, components))
        frame = decode_frame(packet.payload, DEVICE_ID, "analog")
        time_ns, sample_ns, _ = recorder.add(frame)
        yield frame, time_ns, sample_ns

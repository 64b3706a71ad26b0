"""The replay server against the vendor's client (``qtm_rt``) and against a raw client: every
value the client decodes equals the session as ingest reads it (from the folder and from its
MCAP), no frame is lost, the end event arrives, the pace follows the recording's times, and the
protocol's dialogue (versions, refusals, stop and resume, every n-th frame) holds. A twin
session of one short press (about 7 s at 500 Hz) played 50 times faster."""

from __future__ import annotations

import asyncio
import contextlib
import re
import socket
import struct
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from collections.abc import AsyncIterator
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from helpers.paths import ROOT

from core.force_plate import centre_of_pressure
from core.series import RawSession
from data_schema.session import read_session
from ingest.ingest_params import IngestParams
from ingest.ingest_stage import load_session, run_ingest
from ingest.mcap_io import read_raw_mcap
from live.protocol.packets import Event, Packet, PacketReader, PacketType, encode_command, text_of
from live.replay.replay_params import ReplayParams
from live.replay.server import ReplayServer
from live.replay.source import read_replay_source
from pipeline.cli import cli
from sim.twin.synth_params import SynthParams
from sim.twin.synth_stage import run_synth

qtm_rt = pytest.importorskip("qtm_rt")

SPEED = 50.0
COMPONENTS = ["3d", "3dnolabels", "analog", "force"]
WAIT_S = 20.0                 # the longest any answer may take on a busy machine


@pytest.fixture(scope="module")
def replay_twin(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One short press, its force through QTM's analog board (the mocap's clock)."""
    return run_synth(None, tmp_path_factory.mktemp("replay") / "twin", SynthParams(
        seed=3, locations=1, repeats=1, force_via="analog", press_seconds=2.0,
        pivot_seconds=2.0))


@pytest.fixture(scope="module")
def replay_mcap(replay_twin: Path) -> Path:
    out = replay_twin.parent / "twin.mcap"
    run_ingest(replay_twin, out, IngestParams(), None)
    return out


@contextlib.asynccontextmanager
async def serving(path: Path, speed: float = SPEED) -> AsyncIterator[ReplayServer]:
    server = ReplayServer(read_replay_source(path), ReplayParams(port=0, speed=speed))
    await server.start()
    try:
        yield server
    finally:
        await server.close()


async def vendor_stream(port: int, components: list[str],
                        parameters: tuple[str, ...] = ("general", "3d", "analog")
                        ) -> tuple[str, list, list]:
    """Connect with the SDK, ask the ``parameters``, stream until the end event: (XML,
    packets, events)."""
    ended, events = asyncio.Event(), []

    def on_event(event: object) -> None:
        events.append(event)
        if event == qtm_rt.QRTEvent.EventRTfromFileStopped:
            ended.set()

    conn = await qtm_rt.connect("127.0.0.1", port=port, version="1.25", on_event=on_event)
    assert conn is not None
    xml = await conn.get_parameters(list(parameters))
    packets: list = []
    assert await conn.stream_frames(components=components, on_packet=packets.append) == b"Ok"
    await asyncio.wait_for(ended.wait(), WAIT_S)
    conn.disconnect()
    return xml.decode(), packets, events


# -- every value, through the vendor's client --------------------------------------------------

def _session(which: str, request: pytest.FixtureRequest) -> tuple[Path, RawSession]:
    if which == "folder":
        folder = request.getfixturevalue("replay_twin")
        return folder, load_session(read_session(folder))
    mcap = request.getfixturevalue("replay_mcap")
    return mcap, read_raw_mcap(mcap)


@pytest.mark.parametrize("which", ["folder", "mcap"])
def test_vendor_client_decodes_the_session(which, request):
    path, s = _session(which, request)

    async def run() -> tuple[str, list, list, int]:
        async with serving(path) as server:
            xml, packets, events = await vendor_stream(server.port, COMPONENTS)
            return xml, packets, events, server.stats.frames_sent

    xml, packets, events, sent = asyncio.run(run())
    labels = s.phantom_markers + s.indenter_markers
    _check_parameters(ET.fromstring(xml), s, labels)
    frames = s.markers.frames
    assert sent == len(packets) == frames                     # not one frame lost
    assert [p.framenumber for p in packets] == list(range(1, frames + 1))
    assert [p.timestamp for p in packets] == list((s.markers.time_ns + 500) // 1000)
    assert events == [qtm_rt.QRTEvent.EventRTfromFileStopped]
    markers = np.array([[tuple(m) for m in p.get_3d_markers()[1]] for p in packets], np.float32)
    want = np.float32(s.markers.select(labels) * 1e3)
    assert np.isnan(want).any()                               # lost markers are checked too
    np.testing.assert_array_equal(markers, want)              # mm, float32, NaN where lost
    for p, frame in zip(packets, want, strict=True):
        seen = np.flatnonzero(~np.isnan(frame).any(axis=1))
        unlabelled = p.get_3d_markers_no_label()[1]          # the markers seen, with ids
        assert [m.id for m in unlabelled] == list(seen + 1)
        np.testing.assert_array_equal([m[:3] for m in unlabelled], frame[seen].reshape(-1, 3))
        assert p.get_force() == (qtm_rt.packet.RTForceComponent(0), [])     # no plate
    _check_analog(packets, s)


def _check_parameters(root: ET.Element, s: RawSession, labels: list[str]) -> None:
    assert root.tag == "QTM_Parameters_Ver_1.25"
    assert float(root.findtext("General/Frequency")) == s.markers.rate_hz
    assert [n.text for n in root.iterfind("The_3D/Label/Name")] == labels
    assert root.findtext("The_3D/Labels") == str(len(labels))
    (device,) = root.iterfind("Analog/Device")
    assert device.findtext("Device_ID") == "1" and float(device.findtext("Frequency")) == \
        s.force.rate_hz
    assert device.findtext("Channels") == str(len(s.force.channels))
    assert [c.findtext("Label") for c in device.iterfind("Channel")] == s.force.channels
    assert [c.findtext("Unit") for c in device.iterfind("Channel")] == ["V"] * 6


def _check_analog(packets: list, s: RawSession) -> None:
    """Each frame carries its own samples (by time), numbered on from the last frame's; all
    of them together are the session's force, sample for sample."""
    f, t_frames = s.force, s.markers.time_ns
    half, period = 500_000_000 // int(f.rate_hz), int(1e9 / s.markers.rate_hz)
    numbers, values = [], []
    for i, p in enumerate(packets):
        channels = p.get_analog()[1]                          # one entry per channel
        assert [d.id for d, _, _ in channels] == [1] * len(f.channels)
        first = channels[0][1].sample_number
        assert {n.sample_number for _, n, _ in channels} == {first}
        block = np.array([c.samples for _, _, c in channels]).T
        t = f.time_ns[first:first + len(block)]
        assert np.all(t >= t_frames[i] - half) and np.all(t < t_frames[i] + period - half)
        numbers.append(np.arange(first, first + len(block)))
        values.append(block)
    np.testing.assert_array_equal(np.concatenate(numbers), np.arange(f.frames))
    np.testing.assert_array_equal(np.concatenate(values), np.float32(f.values))


@pytest.fixture(scope="module")
def replay_plate(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One short press, its force from a force plate under the phantom (the mocap's clock)."""
    return run_synth(None, tmp_path_factory.mktemp("replay_plate") / "twin", SynthParams(
        seed=3, locations=1, repeats=1, force_via="plate", press_seconds=2.0,
        pivot_seconds=2.0))


def test_vendor_client_decodes_the_force_plate(replay_plate):
    """A session whose force a plate measured is served as that plate: its parameters (id,
    rate, name, type, corners; no analog device), and per frame the force component with the
    plate's forces falling in it, numbered on, each its force and moment as the session has
    them and its point of application (mm) where their line of action meets the plate."""
    s = load_session(read_session(replay_plate))

    async def run() -> tuple[str, list]:
        async with serving(replay_plate) as server:
            xml, packets, _ = await vendor_stream(server.port, ["3d", "analog", "force"],
                                                  ("general", "3d", "analog", "force"))
            return xml, packets

    xml, packets = asyncio.run(run())
    root = ET.fromstring(xml)
    assert root.find("Analog/Device") is None and root.findtext("Force/Unit_Force") == "N"
    (plate,) = root.iterfind("Force/Plate")
    assert (plate.findtext("Plate_ID"), plate.findtext("Name"), plate.findtext("Type")) == \
        ("1", "Force-plate 1", "Kistler")
    assert float(plate.findtext("Frequency")) == s.force.rate_hz == 1000.0
    corners = [[float(plate.findtext(f"Location/Corner{k}/{a}")) for a in "XYZ"]
               for k in range(1, 5)]
    np.testing.assert_allclose(corners, s.force.meta["plate_corners_mm"], atol=1e-6)
    assert len(packets) == s.markers.frames
    f, t_frames = s.force, s.markers.time_ns
    half, period = 500_000, int(1e9 / s.markers.rate_hz)
    numbers, values = [], []
    for i, p in enumerate(packets):
        assert p.get_analog()[1] == []                          # no analog device
        info, plates = p.get_force()
        assert info.plate_count == 1 and len(plates) == 1
        head, forces = plates[0]
        assert head.id == 1 and head.force_count == len(forces) == 2
        t = f.time_ns[head.force_number:head.force_number + len(forces)]
        assert np.all(t >= t_frames[i] - half) and np.all(t < t_frames[i] + period - half)
        numbers.append(np.arange(head.force_number, head.force_number + len(forces)))
        values += [tuple(x) for x in forces]
    np.testing.assert_array_equal(np.concatenate(numbers), np.arange(f.frames))
    cop = centre_of_pressure(f.values[:, :3], f.values[:, 3:]) * 1e3
    np.testing.assert_array_equal(np.array(values, np.float32),
                                  np.float32(np.column_stack([f.values, cop])))
    assert np.abs(cop[np.abs(f.values[:, 2]) > 1, :2]).max() < 60    # under the phantom


def test_clients_one_after_another_and_one_that_leaves_midway(replay_mcap):
    """The first client leaves mid-stream; the next still gets every frame from the first;
    with ``max_clients`` the server then ends on its own."""
    source = read_replay_source(replay_mcap)

    async def run() -> tuple[int, list, ReplayServer]:
        server = ReplayServer(source, ReplayParams(port=0, speed=SPEED, max_clients=2))
        serve = asyncio.create_task(server.serve())
        while server.port is None:
            await asyncio.sleep(0.01)
        got, some = asyncio.Event(), []
        conn = await qtm_rt.connect("127.0.0.1", port=server.port)
        await conn.stream_frames(components=["3d"], on_packet=lambda p: (
            some.append(p), len(some) >= 200 and got.set()))
        await asyncio.wait_for(got.wait(), WAIT_S)
        conn.disconnect()
        _, packets, _ = await vendor_stream(server.port, ["3d", "analog"])
        await asyncio.wait_for(serve, WAIT_S)
        return len(some), packets, server

    first, packets, server = asyncio.run(run())
    assert [p.framenumber for p in packets] == list(range(1, source.frames + 1))
    assert server.stats.clients == server.stats.left == 2
    assert source.frames + first <= server.stats.frames_sent < 2 * source.frames


# -- the protocol's dialogue, through a raw client ----------------------------------------------

class RawClient:
    """A client of packets: what :class:`PacketReader` splits off the socket."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader, self.writer = reader, writer
        self.packets, self.queue = PacketReader(), []

    async def next(self) -> Packet:
        while not self.queue:
            data = await asyncio.wait_for(self.reader.read(1 << 16), WAIT_S)
            if not data:
                raise EOFError
            self.queue += self.packets.feed(data)
        return self.queue.pop(0)

    def send(self, text: str) -> None:
        self.writer.write(encode_command(text))

    async def ask(self, text: str) -> tuple[int, str]:
        self.send(text)
        p = await self.next()
        return p.type, text_of(p.payload)

    async def frames_until(self, kind: PacketType) -> tuple[list[tuple[int, int, int]], Packet]:
        """(frame, first sample, samples) of each data packet until one of ``kind``."""
        frames = []
        while (p := await self.next()).type == PacketType.DATA:
            frames.append(_frame(p.payload))
        assert p.type == kind, p
        return frames, p


def _frame(payload: bytes) -> tuple[int, int, int]:
    """A data packet's frame number and its analog samples' first number and count (the
    frame's components: 3D, then analog)."""
    frame = struct.unpack_from("<qII", payload, 0)[1]
    pos = 16 + struct.unpack_from("<I", payload, 16)[0]      # past the 3D component
    _, _, samples, first = struct.unpack_from("<IIII", payload, pos + 12)
    return frame, first, samples


def test_dialogue_versions_refusals_stop_resume_and_the_end(replay_twin):
    async def run() -> None:
        async with serving(replay_twin) as server:
            c = RawClient(*await asyncio.open_connection("127.0.0.1", server.port))
            assert text_of((await c.next()).payload) == "QTM RT Interface connected"
            assert await c.ask("Version") == (1, "Version is 1.25")
            assert await c.ask("Version 1.7") == (0, "Version 1.7 NOT supported")
            assert await c.ask("Version 2.0") == (0, "Version 2.0 NOT supported")
            assert await c.ask("version 1.20") == (1, "Version set to 1.20")
            kind, xml = await c.ask("GetParameters General")
            assert kind == 2 and ET.fromstring(xml).tag == "QTM_Parameters_Ver_1.20"
            kind, xml = await c.ask("GetParameters Force")
            force = ET.fromstring(xml).find("Force")
            assert force.findtext("Unit_Force") == "N" and force.find("Plate") is None
            assert await c.ask("ByteOrder") == (1, "Byte order is little endian")
            assert await c.ask("Take control") == (0, "Parse error")
            assert (await c.ask("GetParameters 6D"))[0] == 0
            assert await c.ask("GetState") == (6, chr(Event.RT_FROM_FILE_STARTED))
            kind, _ = await c.ask("GetCurrentFrame 3D")
            assert kind == PacketType.DATA
            await _every_tenth_then_stop_and_resume(c, server.source.frames)
            assert await c.ask("GetState") == (6, chr(Event.RT_FROM_FILE_STOPPED))
            assert (await c.ask("StreamFrames AllFrames 3D")) == (PacketType.NO_MORE_DATA, "")
            c.send("ByeBye")
            with pytest.raises(EOFError):
                await c.next()

    asyncio.run(run())


async def _every_tenth_then_stop_and_resume(c: RawClient, frames: int) -> None:
    """Every tenth frame, carrying every sample; a stop between two frames; all frames from
    there to the end; the end event after the last."""
    c.send("StreamFrames FrequencyDivisor:10 3D Analog")
    tenth = [_frame((await c.next()).payload) for _ in range(20)]
    c.send("StreamFrames Stop")
    c.send("ByteOrder")                      # answered once the stream has stopped
    late, _ = await c.frames_until(PacketType.COMMAND)
    c.send("StreamFrames AllFrames 3D Analog")
    rest, end = await c.frames_until(PacketType.EVENT)
    assert end.payload == bytes([Event.RT_FROM_FILE_STOPPED])
    sent = tenth + late + rest
    numbers = [f for f, _, _ in sent]
    stopped = len(tenth + late)
    assert numbers[:stopped] == list(range(1, 10 * stopped, 10))   # frames 1, 11, 21, ...
    assert numbers[stopped:] == list(range(numbers[stopped - 1] + 1, frames + 1))
    samples = [(first, n) for _, first, n in sent]
    assert all(a + n == b for (a, n), (b, _) in zip(samples, samples[1:], strict=False))
    assert samples[0][0] == 0                # no sample lost, none sent twice


def test_frames_keep_to_the_recordings_times(replay_mcap):
    """At 10 times real time, counted from the request: no frame early, and no drift by the
    last."""
    speed = 10.0

    async def run() -> tuple[np.ndarray, np.ndarray]:
        async with serving(replay_mcap, speed) as server:
            c = RawClient(*await asyncio.open_connection("127.0.0.1", server.port))
            await c.next()
            c.send("StreamFrames AllFrames 3D")
            asked, arrivals = time.monotonic(), []
            for _ in range(server.source.frames):
                assert (await c.next()).type == PacketType.DATA
                arrivals.append(time.monotonic())
            return np.array(arrivals) - asked, server.source.time_ns

    arrived, times = asyncio.run(run())
    late = arrived - (times - times[0]) * 1e-9 / speed
    assert late.min() >= 0                          # never ahead of the recording
    assert late[-1] < 0.5, f"{late[-1]:.3f} s behind at the end"


# -- the command ------------------------------------------------------------------------------

def test_bad_input_is_one_line(tmp_path, replay_mcap):
    not_mcap = tmp_path / "x.mcap"
    not_mcap.write_text("hello")
    busy = socket.create_server(("127.0.0.1", 0))
    port = busy.getsockname()[1]
    cases = [([str(tmp_path / "none")], "none: no such session folder or MCAP file"),
             ([str(tmp_path)], "no session.toml in this folder"),
             ([str(not_mcap)], "x.mcap: not an MCAP file"),
             ([str(replay_mcap), "--port", str(port)], f"127.0.0.1:{port}: cannot listen"),
             ([str(replay_mcap), "--speed", "0"], "--speed 0: must be in (0, 1000]"),
             ([str(replay_mcap), "--speed", "inf"], "--speed inf: not a finite number")]
    with busy:
        for args, words in cases:
            res = CliRunner().invoke(cli, ["-q", "replay", *args])
            assert res.exit_code == 2 and isinstance(res.exception, SystemExit), res.output
            lines = res.stderr.strip().splitlines()
            assert len(lines) == 1 and words in lines[0], (args, res.stderr)


def test_the_command_serves_and_reports(replay_mcap):
    """``pipeline replay MCAP --port 0 --max-clients 1``: the port it says, one client served
    to the end, one closing line."""
    proc = subprocess.Popen([sys.executable, "-m", "pipeline", "replay", str(replay_mcap),
                             "--port", "0", "--speed", str(SPEED), "--max-clients", "1"],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        said = proc.stderr.readline()
        port = int(re.search(r"on 127\.0\.0\.1:(\d+) ", said).group(1))
        _, packets, _ = asyncio.run(vendor_stream(port, ["3d"]))
        out, err = proc.communicate(timeout=WAIT_S)
    finally:
        proc.kill()
    frames = read_replay_source(replay_mcap).frames
    assert proc.returncode == 0, err
    assert len(packets) == frames
    assert re.fullmatch(rf".*twin\.mcap: {frames:,} frames sent to 1 client in [\d.]+ s\n", out)

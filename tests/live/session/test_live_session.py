"""``pipeline live`` against the replay server: the session it records is the session ingest
reads from the exports, frame for frame; sync runs on it; what it refuses, it refuses before
a frame is written, in one line; a connection lost mid-frame keeps every complete frame."""

from __future__ import annotations

import asyncio
import contextlib
import shutil
import signal
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from helpers.bad_input_checks import TINY_RUN
from helpers.cgnn_data import write_dent_states
from helpers.live_replay import STATE_KEYS, assert_same_states, offline_states, replaying
from helpers.paths import ROOT

from core.errors import BadInput
from core.recording import rrd_entities
from data_schema.hdf5 import read_h5
from data_schema.states import STATES
from ingest.ingest_params import IngestParams
from ingest.ingest_stage import run_ingest
from ingest.mcap_io import read_raw_mcap
from live.protocol.packets import Component, PacketType, encode_text
from live.replay.parameters import parameters_xml
from live.replay.source import read_replay_source
from live.session.live_params import LiveParams
from live.session.live_stage import MCAP_NAME, RRD_NAME, STATES_NAME, run_live
from pipeline.cli import cli
from sync.sync import sync_session


@pytest.fixture(scope="module")
def recorded(twin_session: Path, tmp_path_factory: pytest.TempPathFactory):
    """The twin session recorded live from the replay, and the same session ingested."""
    out = tmp_path_factory.mktemp("recorded") / "live"
    with replaying(twin_session) as server:
        summary = run_live(twin_session, out, LiveParams(port=server.port, timeout_s=10),
                           out / RRD_NAME)
        sent = server.stats.frames_sent
    ingested = out.parent / "ingested.mcap"
    run_ingest(twin_session, ingested, IngestParams(), None)
    return summary, sent, read_raw_mcap(out / MCAP_NAME), read_raw_mcap(ingested), out


def test_every_frame_sent_is_recorded_once(recorded) -> None:
    summary, sent, live, ingested, out = recorded
    assert summary.counts.frames == sent == ingested.markers.frames
    assert summary.counts.skipped == 0
    assert summary.ended == "QTM stopped playing the file"
    assert not (out / (MCAP_NAME + ".part")).exists()      # the journal became the MCAP


def test_the_live_session_is_the_ingested_session(recorded) -> None:
    """Markers to float32 millimetres (what the protocol carries), the force's volts to
    float32, the same clocks, channels, units, calibration and pivot recording."""
    _, _, live, ingested, _ = recorded
    lm, im = live.markers, ingested.markers
    np.testing.assert_array_equal(lm.time_ns, im.time_ns)
    assert lm.rate_hz == im.rate_hz and lm.labels == im.labels
    np.testing.assert_array_equal(np.isnan(lm.positions), np.isnan(im.positions))
    np.testing.assert_allclose(lm.positions, im.positions, atol=1e-7, equal_nan=True)
    lf, inf = live.force, ingested.force
    np.testing.assert_array_equal(lf.time_ns, inf.time_ns)
    assert (lf.channels, lf.units, lf.kind, lf.rate_hz) == \
        (inf.channels, inf.units, inf.kind, inf.rate_hz)
    assert lf.meta["clock"] == inf.meta["clock"] == "mocap"
    np.testing.assert_allclose(lf.values, inf.values, rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(live.calibration.matrix, ingested.calibration.matrix)
    np.testing.assert_array_equal(live.pivot.positions, ingested.pivot.positions)
    assert (live.phantom_markers, live.indenter_markers) == \
        (ingested.phantom_markers, ingested.indenter_markers)


def test_sync_finds_the_same_presses_on_the_live_session(recorded) -> None:
    _, _, live, ingested, _ = recorded
    a, b = sync_session(live), sync_session(ingested)
    assert [(p.press.onset, p.press.release) for p in a.presses] == \
        [(p.press.onset, p.press.release) for p in b.presses]
    np.testing.assert_allclose(a.pivot.tip_body, b.pivot.tip_body, atol=1e-9)
    for pa, pb in zip(a.presses, b.presses, strict=True):
        np.testing.assert_allclose(pa.force_magnitude, pb.force_magnitude, atol=1e-4)


def test_presses_seen_live_are_syncs_and_the_states_are_extracts(recorded, tmp_path) -> None:
    """The presses, locations and states taken live, press by press as the session went on,
    are those ingest, sync and extract give on the exports afterwards: the same presses and
    levels, points within 0.05 mm, forces within 1 mN."""
    summary, _, _, ingested, out = recorded
    offline = offline_states(out.parent / "ingested.mcap", tmp_path / "offline")
    synced = sync_session(ingested)
    assert summary.presses == len(synced.presses)
    assert len(summary.locations) == len(synced.location_centres)
    want, _ = read_h5(offline, STATES)
    assert summary.states.startswith(f"{len(want['states/points'])} states")
    assert_same_states(out / STATES_NAME, offline)
    assert [c.presses for c in summary.locations] == [1, 1, 1, 1]


def test_the_recording_shows_the_scene_the_force_and_the_status(recorded) -> None:
    *_, out = recorded
    entities = rrd_entities(out / RRD_NAME)
    for path, archetype in (("/scene/phantom", "Points3D"), ("/scene/cluster", "Points3D"),
                            ("/scene/tip", "Points3D"), ("/force/magnitude", "Scalars"),
                            ("/quality/lost", "Scalars"), ("/quality/saturated", "Scalars"),
                            ("/scene/coverage", "Points3D"),
                            ("/status", "TextLog")):
        assert archetype in entities.get(path, set()), path


def test_a_press_whose_stretch_is_refused_is_said_and_the_session_goes_on(
        twin_session, recorded, tmp_path, monkeypatch) -> None:
    """Sync's steps refusing one press's stretch on the worker thread (a bad stretch, as
    offline sync would refuse it) leave that press out, in one warning line on stderr and in
    the status log; the frames, the other presses and their states go on."""
    from live.session import states as live_states

    read = live_states.press_record

    def refusing(stretch, done, on):
        if done.number == 2:
            raise BadInput(None, "markers lost beyond repair in its stretch")
        return read(stretch, done, on)

    monkeypatch.setattr(live_states, "press_record", refusing)
    out = tmp_path / "live"
    with replaying(twin_session) as server:
        code, err = _live(twin_session, server.port, out)
    assert code == 0, err
    assert err.count("press 2: its states were not read: markers lost beyond repair") == 1
    got, _ = read_h5(out / STATES_NAME, STATES)
    whole, _ = read_h5(recorded[4] / STATES_NAME, STATES)
    seq = whole["states/sequence"]
    kept = [np.flatnonzero(seq != k) for k in np.unique(seq)]
    assert any(len(k) == len(got["states/force"]) and np.allclose(
        whole["states/force"][k], got["states/force"], atol=1e-3) for k in kept)
    assert read_raw_mcap(out / MCAP_NAME).markers.frames == recorded[2].markers.frames
    assert "press 2: its states were not read" in " ".join(_texts(out / RRD_NAME, "/status"))


def _texts(rrd: Path, entity: str) -> list[str]:
    """The lines of a text log in a recording."""
    from rerun.chunk import RrdReader

    lines = []
    for chunk in RrdReader(str(rrd)).store().stream():
        if chunk.entity_path == entity:
            batch = chunk.to_record_batch()
            if "TextLog:text" in batch.column_names:
                lines += [str(v) for row in batch.column("TextLog:text").to_pylist()
                          for v in (row or [])]
    return lines


def _session_copy(twin_session: Path, tmp_path: Path, old: str, new: str) -> Path:
    folder = tmp_path / "edited"
    shutil.copytree(twin_session, folder)
    toml = folder / "session.toml"
    assert old in toml.read_text()
    toml.write_text(toml.read_text().replace(old, new))
    return folder


def _live(session: Path, port: int, out: Path, timeout: str = "10") -> tuple[int, str]:
    res = CliRunner().invoke(cli, ["live", str(session), "--qtm", f"127.0.0.1:{port}",
                                   "--out", str(out), "--timeout", timeout])
    return res.exit_code, res.stderr


@pytest.mark.parametrize(("old", "new", "words"), [
    ('"P24"]', '"P99"]', "marker(s) named in session.toml not in file: P99"),
    ('kind = "gauge"', 'kind = "wrench"', "as the file states, but force.units says N"),
])
def test_a_session_qtm_contradicts_is_refused_before_a_frame(twin_session, tmp_path, old,
                                                             new, words) -> None:
    session = _session_copy(twin_session, tmp_path, old, new)
    with replaying(twin_session) as server:
        code, err = _live(session, server.port, tmp_path / "out")
    assert code == 2 and words in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_no_server_is_one_line(twin_session, tmp_path) -> None:
    with replaying(twin_session) as server:
        port = server.port
    code, err = _live(twin_session, port, tmp_path / "out", timeout="1")
    assert code == 2 and "no QTM real-time server answered within 1 s" in err
    assert not (tmp_path / "out").exists()


async def _cut_server(source, frames: int, cut: int) -> tuple[asyncio.AbstractServer, int]:
    """A server that greets, answers the version and the parameters, then sends ``frames``
    frames of ``source`` and the first ``cut`` bytes of the next, and hangs up."""
    from live.replay.frames import frame_packet

    async def client(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        writer.write(encode_text(PacketType.COMMAND, "QTM RT Interface connected"))
        for answer in ("Version set to 1.25", None):
            await _command(reader)
            text = parameters_xml(source, ("general", "3d", "analog"), "1.25") \
                if answer is None else answer
            kind = PacketType.XML if answer is None else PacketType.COMMAND
            writer.write(encode_text(kind, text))
        await _command(reader)
        for i in range(frames + 1):
            packet = frame_packet(source, i, [Component.THREE_D, Component.ANALOG])
            writer.write(packet if i < frames else packet[:cut])
        await writer.drain()
        writer.close()

    server = await asyncio.start_server(client, "127.0.0.1", 0)
    return server, server.sockets[0].getsockname()[1]


async def _command(reader: asyncio.StreamReader) -> None:
    size, _ = struct.unpack("<II", await reader.readexactly(8))
    await reader.readexactly(size - 8)


def test_a_connection_lost_mid_frame_keeps_every_complete_frame(twin_session, tmp_path):
    source, frames = read_replay_source(twin_session), 700
    loop = asyncio.new_event_loop()
    server, port = loop.run_until_complete(_cut_server(source, frames, cut=100))
    thread = threading.Thread(target=loop.run_forever, daemon=True)
    thread.start()
    try:
        code, err = _live(twin_session, port, tmp_path / "out")
    finally:
        loop.call_soon_threadsafe(server.close)
        loop.call_soon_threadsafe(loop.stop)
        thread.join(10)
    assert code == 2 and "connection" in err and len(err.strip().splitlines()) == 1
    kept = read_raw_mcap(tmp_path / "out" / MCAP_NAME)
    assert kept.markers.frames == frames


async def _flaky_proxy(port: int, cut: int) -> tuple[asyncio.AbstractServer, int]:
    """A proxy to the server on ``port`` whose first connection is hung up after ``cut`` bytes
    from the server (mid-frame); later connections pass everything."""
    seen = []

    async def pipe(src: asyncio.StreamReader, dst: asyncio.StreamWriter,
                   limit: int | None) -> None:
        sent = 0
        with contextlib.suppress(ConnectionError):
            while data := await src.read(65536):
                if limit is not None and sent + len(data) >= limit:
                    dst.write(data[:limit - sent])
                    break
                dst.write(data)
                sent += len(data)
                await dst.drain()
        dst.close()

    async def client(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        seen.append(writer)
        up_reader, up_writer = await asyncio.open_connection("127.0.0.1", port)
        down = asyncio.ensure_future(pipe(up_reader, writer, cut if len(seen) == 1 else None))
        up = asyncio.ensure_future(pipe(reader, up_writer, None))
        await down
        up_writer.close()
        up.cancel()

    server = await asyncio.start_server(client, "127.0.0.1", 0)
    return server, server.sockets[0].getsockname()[1]


def test_a_reconnection_goes_on_into_the_same_session(twin_session, recorded, tmp_path):
    """The connection cut mid-frame, ``--reconnect`` connects again and the server starts
    over: every frame is recorded once, the MCAP is the uninterrupted session's, and the
    states taken live are too."""
    whole, states = recorded[2], recorded[4] / STATES_NAME
    with replaying(twin_session) as server:
        loop = asyncio.new_event_loop()
        proxy, port = loop.run_until_complete(_flaky_proxy(server.port, cut=1_500_000))
        thread = threading.Thread(target=loop.run_forever, daemon=True)
        thread.start()
        try:
            summary = run_live(twin_session, tmp_path / "out", LiveParams(
                port=port, timeout_s=10, reconnect_s=10), None)
        finally:
            loop.call_soon_threadsafe(proxy.close)
            loop.call_soon_threadsafe(loop.stop)
            thread.join(10)
    assert summary.counts.resent > 1000
    kept = read_raw_mcap(tmp_path / "out" / MCAP_NAME)
    np.testing.assert_array_equal(kept.markers.positions, whole.markers.positions)
    np.testing.assert_array_equal(kept.force.values, whole.force.values)
    got, _ = read_h5(tmp_path / "out" / STATES_NAME, STATES)
    want, _ = read_h5(states, STATES)
    np.testing.assert_array_equal(got["states/points"], want["states/points"])


def _tiny_run(states: Path, out: Path) -> Path:
    """One optimiser step of the paper's network on ``states``: a model of its markers."""
    runner = CliRunner()
    for args in (("split", states, "--out", out / "splits.json", "--folds", "3", "--ratio",
                  "1:1:1", "--group", "sequence", "--no-rrd"),
                 ("train", "--data", states, "--splits", out / "splits.json", "--out",
                  out / "run", *TINY_RUN)):
        res = runner.invoke(cli, [str(a) for a in args])
        assert res.exit_code == 0, res.output
    return out / "run"


def test_the_models_answer_is_shown_beside_each_press(recorded, twin_session, tmp_path):
    """A model of this phantom's markers (trained on the session's own states, one step: the
    view is checked, not the model) answers at each drawing of a press: its surface, its L_d
    against the markers and its force error are in the recording."""
    *_, out = recorded
    run = _tiny_run(out / STATES_NAME, tmp_path)
    with replaying(twin_session) as server:
        summary = run_live(twin_session, tmp_path / "live", LiveParams(
            port=server.port, timeout_s=10, model=run, states=False), tmp_path / "live.rrd")
    assert summary.presses == recorded[0].presses
    entities = rrd_entities(tmp_path / "live.rrd")
    for path, archetype in (("/scene/model", "Points3D"), ("/model/ld_mm", "Scalars"),
                            ("/model/force_error_n", "Scalars")):
        assert archetype in entities.get(path, set()), path


def test_a_model_of_another_phantoms_markers_is_refused(twin_session, tmp_path) -> None:
    write_dent_states(tmp_path / "dent.h5", places=3, steps=4)
    run = _tiny_run(tmp_path / "dent.h5", tmp_path)
    with replaying(twin_session) as server:
        res = CliRunner().invoke(cli, ["live", str(twin_session), "--qtm",
                                       f"127.0.0.1:{server.port}", "--out",
                                       str(tmp_path / "out"), "--model", str(run)])
    assert res.exit_code == 2 and "another phantom's markers" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and not (tmp_path / "out").exists()


def test_a_killed_session_is_recovered_from_its_journal(twin_session, recorded, tmp_path):
    """SIGKILL mid-stream leaves only the journal; ``--recover`` finishes it as the MCAP: every
    complete block, the session's first frames exactly as recorded uninterrupted."""
    out = tmp_path / "killed"
    part = out / (MCAP_NAME + ".part")
    with replaying(twin_session, speed=2.0) as server:
        proc = subprocess.Popen([sys.executable, "-m", "pipeline", "-q", "live",
                                 str(twin_session), "--qtm", f"127.0.0.1:{server.port}",
                                 "--out", str(out)], cwd=ROOT)
        deadline = time.monotonic() + 60
        while (not part.is_file() or part.stat().st_size < 2_000_000) and \
                time.monotonic() < deadline:
            time.sleep(0.1)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert not (out / MCAP_NAME).exists()
    res = CliRunner().invoke(cli, ["live", str(twin_session), "--out", str(out), "--recover"])
    assert res.exit_code == 0, res.stderr
    assert "ended: recovered from a journal cut short (" in res.stdout
    kept = read_raw_mcap(out / MCAP_NAME)
    whole = recorded[2]
    n = kept.markers.frames
    assert 500 <= n < whole.markers.frames and not part.exists()
    np.testing.assert_array_equal(kept.markers.positions, whole.markers.positions[:n])
    np.testing.assert_array_equal(kept.force.values, whole.force.values[:len(kept.force.values)])
    again = CliRunner().invoke(cli, ["live", str(twin_session), "--out", str(out), "--recover"])
    assert again.exit_code == 2 and "nothing to recover" in again.stderr


def test_a_lab_with_another_marker_layout(tmp_path) -> None:
    """20 markers scattered on the phantom (the twin's ``--markers scattered:20``): the live
    session checks, records and takes states of that layout as the offline stages do."""
    from sim.twin.synth_params import SynthParams
    from sim.twin.synth_stage import run_synth

    session = run_synth(None, tmp_path / "session", SynthParams(
        seed=5, locations=2, repeats=1, force_via="analog", markers="scattered:20"))
    with replaying(session) as server:
        run_live(session, tmp_path / "live", LiveParams(port=server.port, timeout_s=10), None)
    ingested = tmp_path / "ingested.mcap"
    run_ingest(session, ingested, IngestParams(), None)
    offline = offline_states(ingested, tmp_path / "offline")
    live, _ = read_h5(tmp_path / "live" / STATES_NAME, STATES)
    assert live["states/points"].shape[1] == 21
    assert_same_states(tmp_path / "live" / STATES_NAME, offline, STATE_KEYS[:3])


def test_a_curved_phantom(tmp_path) -> None:
    """A dome (the twin's ``--shape dome:30``): the live session registers the markers to the
    mould as sync does, and takes the offline stages' states in the shape's frame."""
    from sim.twin.synth_params import SynthParams
    from sim.twin.synth_stage import run_synth

    session = run_synth(None, tmp_path / "session", SynthParams(
        seed=6, locations=2, repeats=1, force_via="analog", shape="dome:30"))
    rrd = tmp_path / "live.rrd"
    with replaying(session) as server:
        run_live(session, tmp_path / "live", LiveParams(port=server.port, timeout_s=10), rrd)
    ingested = tmp_path / "ingested.mcap"
    run_ingest(session, ingested, IngestParams(), None)
    offline = offline_states(ingested, tmp_path / "offline")
    assert_same_states(tmp_path / "live" / STATES_NAME, offline, STATE_KEYS[:3])
    live, _ = read_h5(tmp_path / "live" / STATES_NAME, STATES)
    assert np.nanmax(live["states/points"][:, :, 2]) > 0.02     # in the shape's frame: the cap
    assert {"/scene/shape", "/scene/phantom", "/scene/tip"} <= set(rrd_entities(rrd))

"""Every way ``pipeline live`` can fail, against a QTM that fails at each step of the
protocol's dialogue (:class:`helpers.live_replay.FaultyQtm`): one line on stderr, exit 2,
every connection the client opened closed by the client (the server saw it close; on Linux the
process's socket count is back where it was, with the garbage collector off so that nothing
closes a leaked socket behind the client's back), nothing written before the first frame, and
after it every frame received kept in session.mcap. Beside them what is no failure: the model
refusing a press (one warning, the session goes on), Ctrl-C and SIGTERM through the event loop
and, where it has no signal handling (Windows), through :mod:`signal`."""

from __future__ import annotations

import asyncio
import gc
import os
import signal
import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner, Result
from helpers.live_replay import FaultyQtm, open_sockets, replaying

from core.recording import rrd_entities
from ingest.mcap_io import read_raw_mcap
from live.protocol.parameters import AnalogDevice, QtmParameters
from live.replay.source import read_replay_source
from live.session.journal import Journal
from live.session.layout import live_layout
from live.session.live_params import LiveParams
from live.session.live_stage import MCAP_NAME, RRD_NAME, _header, run_live
from pipeline.cli import cli
from sync.sync import TIP

FRAMES = 300                  # sent before a mid-stream fault: 0.6 s of the twin at 500 Hz
TIMEOUT = "0.5"               # seconds a silent step is waited for


def _live(session: Path, faults: list[str], out: Path, *options: str, frames: int = FRAMES
          ) -> tuple[Result, FaultyQtm, int | None, int | None]:
    """``pipeline live`` against a QTM that follows ``faults`` (``frames`` before a
    mid-stream fault): its result, the server, and the process's open sockets before the
    server started and after it stopped."""
    gc.collect()
    gc.disable()
    try:
        before = open_sockets()
        qtm = FaultyQtm(session, faults, frames)
        try:
            res = CliRunner().invoke(cli, ["live", str(session), "--qtm",
                                           f"127.0.0.1:{qtm.port}", "--out", str(out),
                                           "--timeout", TIMEOUT, "--no-rrd", *options])
        finally:
            qtm.close()
        after = open_sockets()
    finally:
        gc.enable()
    return res, qtm, before, after


def _one_line_and_closed(res: Result, qtm: FaultyQtm, before: int | None, after: int | None,
                         words: str) -> None:
    assert res.exit_code == 2, (res.output, res.exception)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0], res.stderr
    assert qtm.accepted >= 1 and qtm.closed_by_client == qtm.accepted
    assert after == before                    # no socket left open (None: no /proc here)


@pytest.mark.parametrize(("fault", "words"), [
    ("greeting refused", "refused the connection: Connection refused: too many clients"),
    ("version refused", "refused protocol version 1.25: Version 1.25 NOT supported"),
    ("version silent", "did not answer 'Version 1.25' within 0.5 s"),
    ("parameters refused", "refused its parameters: GetParameters: no measurement"),
    ("parameters not xml", "its parameters are not XML"),
    ("marker missing", "marker(s) named in session.toml not in file: P00"),
    ("stream refused", "refused to stream frames: StreamFrames: no measurement running"),
    ("stream no more data", "has no frames to stream (no more data"),
    ("stream silent", "sent no frame within 0.5 s of StreamFrames"),
])
def test_a_failure_before_the_first_frame_writes_nothing(twin_session, tmp_path, fault,
                                                         words) -> None:
    res, qtm, before, after = _live(twin_session, [fault], tmp_path / "out")
    _one_line_and_closed(res, qtm, before, after, words)
    assert not (tmp_path / "out").exists()


def test_no_server_leaves_no_socket(tmp_path, twin_session) -> None:
    """Nothing listens on the port: refused at once, in one line, no socket left."""
    with socket.socket() as s:                  # a port that was free a moment ago
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    gc.disable()
    try:
        before = open_sockets()
        res = CliRunner().invoke(cli, ["live", str(twin_session), "--qtm", f"127.0.0.1:{port}",
                                       "--out", str(tmp_path / "out"), "--timeout", TIMEOUT])
        after = open_sockets()
    finally:
        gc.enable()
    assert res.exit_code == 2 and len(res.stderr.strip().splitlines()) == 1
    assert "no QTM real-time server answered within 0.5 s" in res.stderr
    assert after == before and not (tmp_path / "out").exists()


def _kept_every_frame(out: Path, session: Path) -> None:
    """session.mcap holds the FRAMES frames sent, as sent, and their force samples."""
    source = read_replay_source(session)
    kept = read_raw_mcap(out / MCAP_NAME)
    assert kept.markers.labels == source.labels and kept.markers.frames == FRAMES
    np.testing.assert_array_equal(kept.markers.positions,
                                  source.markers_mm[:FRAMES].astype(np.float64) * 1e-3)
    assert len(kept.force.time_ns) == source.force.bounds[FRAMES] - source.force.bounds[0]
    assert not (out / (MCAP_NAME + ".part")).exists()


@pytest.mark.parametrize(("fault", "words"), [
    ("damaged packet", f"a damaged packet after frame {FRAMES} (frame {FRAMES + 1}: a "
                       "component of"),
    ("impossible size", f"a damaged packet after frame {FRAMES} (packet of 0 bytes"),
    ("wrong marker count", f"frame {FRAMES + 1} carries "),
    ("dropped", f"the connection was lost after frame {FRAMES} of this session: "
                f"session.mcap holds the {FRAMES} frames received before it"),
])
def test_a_failure_mid_stream_keeps_every_frame(twin_session, tmp_path, fault, words) -> None:
    res, qtm, before, after = _live(twin_session, [fault], tmp_path / "out")
    _one_line_and_closed(res, qtm, before, after, words)
    _kept_every_frame(tmp_path / "out", twin_session)


@pytest.mark.parametrize(("fault", "words"), [
    ("damaged packet", "a damaged packet before its first frame (frame 1: a component of"),
    ("wrong marker count", "frame 1 carries "),
])
def test_a_first_frame_refused_writes_nothing(twin_session, tmp_path, fault, words) -> None:
    """Refused at the first frame: no MCAP, no recording, no journal, no folder."""
    res, qtm, before, after = _live(twin_session, [fault], tmp_path / "out", frames=0)
    _one_line_and_closed(res, qtm, before, after, words)
    assert "no frame was recorded, nothing written" in res.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(("faults", "words"), [
    (["dropped"], "the connection was lost after frame 300 of this session (no answer for "
                  "--reconnect 1 s)"),
    (["dropped", "another capture"], "reconnected, but QTM now streams another capture"),
    (["dropped", "marker missing"], "marker(s) named in session.toml not in file: P00"),
    (["dropped", "parameters not xml"], "its parameters are not XML"),
    (["dropped", "stream refused"], "refused to stream frames"),
])
def test_a_failed_reconnection_keeps_every_frame(twin_session, tmp_path, faults,
                                                 words) -> None:
    """The connection lost mid-frame; ``--reconnect 1`` meets a server that is gone (its
    port refuses), streams another capture, lacks a marker, sends no parameters document or
    will not stream: refused in one line, both connections closed, the frames kept."""
    res, qtm, before, after = _live(twin_session, faults, tmp_path / "out", "--reconnect", "1")
    _one_line_and_closed(res, qtm, before, after, words)
    assert qtm.accepted == len(faults)
    _kept_every_frame(tmp_path / "out", twin_session)


class _RefusingPredictor:
    """A trained run of the session's points that answers "nothing moves", and refuses every
    answer for the second press it is asked about (as the predictor refuses a surface far
    from what it learned)."""

    def __init__(self, names: list[str]) -> None:
        self.point_names, self.starts = names, []

    def predict(self, points: np.ndarray, condition: np.ndarray, region: float | None = None
                ) -> tuple[np.ndarray, float]:
        start = tuple(np.round(condition[:3], 6))
        if start not in self.starts:
            self.starts.append(start)
        if self.starts.index(start) == 1:
            raise ValueError("points lie 9.1 m from the training data's centre")
        return points.copy(), 0.0


def test_a_press_the_model_refuses_is_one_warning_and_the_session_goes_on(
        twin_session, tmp_path, monkeypatch) -> None:
    from data_schema.session import read_session
    from live.session import model

    cfg = read_session(twin_session)
    fake = _RefusingPredictor(list(cfg.mocap.phantom_markers) + [TIP])
    monkeypatch.setattr(model.Predictor, "load", staticmethod(lambda run: fake))
    out = tmp_path / "out"
    with replaying(twin_session) as server:
        res = CliRunner().invoke(cli, ["live", str(twin_session), "--qtm",
                                       f"127.0.0.1:{server.port}", "--out", str(out),
                                       "--timeout", "10", "--model", str(tmp_path)])
        sent = server.stats.frames_sent
    assert res.exit_code == 0, res.stderr
    warnings = [w for w in res.stderr.splitlines() if w.startswith("warning:")]
    assert len(warnings) == 1 and "the model refused the press under way" in warnings[0]
    assert "9.1 m from the training data's centre" in warnings[0]
    assert len(fake.starts) >= 3                           # asked again at the next press
    assert "; the model refused 1 press;" in res.stdout and "4 presses" in res.stdout
    assert read_raw_mcap(out / MCAP_NAME).markers.frames == sent
    assert "Points3D" in rrd_entities(out / RRD_NAME).get("/scene/model", set())


def _stop_when_streaming(part: Path, sig: signal.Signals, done: threading.Event) -> None:
    """Send ``sig`` to this process once the journal holds a few blocks (the session is
    streaming, its handlers set), unless the session has ended meanwhile."""
    deadline = time.monotonic() + 30
    while not done.is_set() and time.monotonic() < deadline:
        if part.is_file() and part.stat().st_size > 200_000:
            os.kill(os.getpid(), sig)
            return
        time.sleep(0.01)


def _stopped_session(session: Path, out: Path, sig: signal.Signals):
    """A live session of the replay at twice real time, stopped by ``sig`` mid-stream."""
    done = threading.Event()
    with replaying(session, speed=2.0) as server:
        sender = threading.Thread(target=_stop_when_streaming,
                                  args=(out / (MCAP_NAME + ".part"), sig, done))
        sender.start()
        try:
            summary = run_live(session, out, LiveParams(port=server.port, timeout_s=10,
                                                        states=False), None)
        finally:
            done.set()
            sender.join()
    return summary, server.stats.frames_sent


def test_sigterm_stops_the_session_through_the_loop(twin_session, tmp_path) -> None:
    summary, sent = _stopped_session(twin_session, tmp_path / "out", signal.SIGTERM)
    assert summary.ended == "stopped by SIGTERM"
    assert 0 < summary.counts.frames < read_replay_source(twin_session).frames
    assert read_raw_mcap(tmp_path / "out" / MCAP_NAME).markers.frames == summary.counts.frames


def test_ctrl_c_stops_the_session_where_the_loop_has_no_signal_handling(
        twin_session, tmp_path, monkeypatch) -> None:
    """As on Windows' Proactor loop, the loop refuses signal handlers: Ctrl-C goes through
    signal.signal, the stop scheduled on the loop; the handler before is restored after."""
    def refuse(*args: object) -> None:
        raise NotImplementedError

    monkeypatch.setattr(asyncio.SelectorEventLoop, "add_signal_handler", refuse)
    before = signal.getsignal(signal.SIGINT)
    summary, _ = _stopped_session(twin_session, tmp_path / "out", signal.SIGINT)
    assert summary.ended == "stopped by SIGINT"
    assert 0 < summary.counts.frames < read_replay_source(twin_session).frames
    assert read_raw_mcap(tmp_path / "out" / MCAP_NAME).markers.frames == summary.counts.frames
    assert signal.getsignal(signal.SIGINT) is before


MAGIC, CHUNK = 8, 0x06            # an MCAP file's magic bytes, and a chunk record's opcode


def _records(data: bytes) -> list[tuple[int, int]]:
    """(opcode, start) of each whole record of an MCAP file, read by the format's framing
    (magic, then per record u8 opcode, u64 length, body) and not by the library."""
    pos, found = MAGIC, []
    while pos + 9 <= len(data):
        length = int.from_bytes(data[pos + 1:pos + 9], "little")
        if pos + 9 + length > len(data):
            break
        found.append((data[pos], pos))
        pos += 9 + length
    return found


def test_recover_says_the_journal_was_cut_short_and_by_how_much(twin_session, tmp_path):
    """A journal of three blocks per stream, its last block's chunk cut 50 bytes in (a kill
    mid-write): ``--recover`` keeps the five whole blocks and says it dropped those 50 bytes;
    the same journal closed by its session is said to be complete."""
    from data_schema.session import read_session

    cfg = read_session(twin_session)
    labels = cfg.mocap.phantom_markers + cfg.mocap.indenter_markers
    board = AnalogDevice(1, "board", 1000.0, list(cfg.force.channels), ["V"] * 6)
    layout = live_layout(QtmParameters("QTM RT 127.0.0.1:1", 500.0, labels, [board]), cfg)
    for closed in (False, True):
        out = tmp_path / f"closed_{closed}"
        out.mkdir()
        part = out / (MCAP_NAME + ".part")
        journal = Journal(part, _header(layout))
        for i in range(3):
            journal.append("/live/markers", np.arange(i * 10, i * 10 + 10) * 2_000_000,
                           np.zeros((10, 3 * len(labels))))
            journal.append("/live/force", np.arange(i * 20, i * 20 + 20) * 1_000_000,
                           np.zeros((20, 6)))
        if closed:
            journal.close()
        else:
            data = part.read_bytes()
            last = max(start for opcode, start in _records(data) if opcode == CHUNK)
            part.write_bytes(data[:last + 50])
        res = CliRunner().invoke(cli, ["live", str(twin_session), "--out", str(out),
                                       "--recover"])
        assert res.exit_code == 0, res.stderr
        if closed:
            assert "ended: recovered from a complete journal (6 blocks" in res.stdout
            assert read_raw_mcap(out / MCAP_NAME).markers.frames == 30
        else:
            assert "ended: recovered from a journal cut short (5 whole blocks kept, " \
                   "50 bytes of a block cut short dropped" in res.stdout
            assert read_raw_mcap(out / MCAP_NAME).markers.frames == 30
            assert len(read_raw_mcap(out / MCAP_NAME).force.time_ns) == 40

"""The live runner: a session folder and QTM's real-time stream in; the session's MCAP and its
recording out, written as the frames arrive.

Before the first frame: ``session.toml`` is read, QTM's parameters are held against it
(:mod:`live.live_layout`) and the tip is calibrated (:mod:`live.live_calibration`); any of them
that cannot be trusted is refused in one line, and nothing is written. Then every frame goes
into the journal (``session.mcap.part``, :mod:`live.live_journal`) and to the monitor and view,
until ``--duration``, Ctrl-C (or SIGTERM), QTM's end of the recording, a lost connection or a
silent server. However it ended, the journal then becomes ``LIVE_DIR/session.mcap`` in
ingest's layout (``phantom.raw_mcap``; ``pipeline sync`` runs on it as on an ingested file),
with its provenance, and the journal is removed; the recording is renamed into place beside it.
A damaged frame, or a frame that contradicts the parameters, ends the session the same way and
is then refused in one line (exit 2): what arrived before it is kept.
"""

from __future__ import annotations

import asyncio
import contextlib
import signal
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import rerun as rr

from core.atomic import atomic_output
from core.errors import BadInput
from core.provenance import make_provenance
from core.series import MarkerSeries, RawSession
from data_schema.raw_mcap import SCHEMA, VERSION
from data_schema.session import SessionConfig, read_session
from data_schema.states import STATES
from extract.extract import extract
from extract.extract_stage import write_states
from ingest.ati_cal import read_ati_cal
from ingest.detect import read_mocap
from ingest.ingest_stage import session_inputs
from ingest.mcap_io import write_raw_mcap
from live.live_calibration import TipModel, tip_model
from live.live_journal import FORCE, MARKERS, Journal, read_journal
from live.live_layout import LiveLayout, live_layout, to_force
from live.live_model import LiveModel
from live.live_monitor import Monitor
from live.live_params import LiveParams
from live.live_recorder import Counts, Recorder
from live.live_states import Coverage, OnlineStates, coverage
from live.live_view import LiveView
from live.qtm_parameters import device_from_json, device_json, parse_parameters
from live.rt_client import Stream, decode_frame
from sync.sync_params import SyncParams

MCAP_NAME = "session.mcap"
RRD_NAME = "session.rrd"
STATES_NAME = "states.h5"         # the states taken online
RETRY_S = 0.5                     # between attempts to reconnect


@dataclass
class LiveSummary:
    """What a live session received, how it ended, and how long each frame's work took."""

    source: str
    counts: Counts
    ended: str
    mcap: Path
    rrd: Path | None
    seconds: float
    latency_ms: np.ndarray = field(default_factory=lambda: np.empty(0))
    refused: BadInput | None = None       # a frame refused mid-session (after the MCAP)
    locations: list[Coverage] = field(default_factory=list)   # pressed, as seen live
    presses: int = 0
    states: str = ""                      # what became of the session's states
    online: OnlineStates | None = None    # the presses and states taken as they ended


def run_live(inputs: Path, out: Path, params: LiveParams | None = None,
             rrd: Path | None = None) -> LiveSummary:
    """Record the live session of the session folder ``inputs`` into the folder ``out``
    (``session.mcap``), with its recording ``rrd`` (None: none)."""
    params = params or LiveParams()
    cfg = read_session(inputs)
    mcap = Path(out) / MCAP_NAME
    part = mcap.with_name(mcap.name + ".part")
    if params.recover:
        return _recover(part, mcap, cfg, params)
    for path in (mcap, part):
        if path.exists():
            raise BadInput(path, "exists: a live session writes into a new folder (choose "
                                 "another --out; a journal a killed session left is "
                                 "finished with --recover)")
    summary = asyncio.run(_session(cfg, part, params, rrd))
    summary.mcap = mcap
    _finish(part, mcap, cfg, params)
    if params.states and summary.online is not None and summary.refused is None:
        summary.states = _states(summary.online, mcap, params)
    return summary


def _recover(part: Path, mcap: Path, cfg: SessionConfig, params: LiveParams) -> LiveSummary:
    """The journal a killed session left (``session.mcap.part``), every complete block of it,
    finished as ``session.mcap``; nothing is streamed."""
    if not part.is_file():
        raise BadInput(part, "no journal of a killed session here: nothing to recover")
    if mcap.exists():
        raise BadInput(mcap, "exists: the session was finished already")
    content = read_journal(part)
    _finish(part, mcap, cfg, params)
    frames = len(content.streams[MARKERS][0])
    summary = LiveSummary(content.header["source"], Counts(frames, 0,
                                                          len(content.streams[FORCE][0])),
                          "recovered from the journal of a killed session", mcap, None, 0.0)
    return summary


def _states(online: OnlineStates, mcap: Path, params: LiveParams) -> str:
    """The states taken online, written as extract writes a states file
    (``states.h5`` beside the MCAP). Said, not raised, where extract refuses them: the MCAP is
    the session."""
    out = mcap.with_name(STATES_NAME)
    if not online.taken:
        return "no states (no press was taken)"
    ex_params = online.extract
    try:
        session = online.session(mcap)
        ex = extract([session], ex_params)
        prov = make_provenance("live", asdict(params), [mcap], STATES.name, STATES.version)
        write_states(ex, [session], ex_params, prov, out, None)
    except BadInput as e:
        return f"no states ({e.line()})"
    missed = f" ({online.missed} presses sync's rules did not confirm)" if online.missed else ""
    missed += f" ({len(online.unread)} presses not read: their stretch was refused)" \
        if online.unread else ""
    return f"{len(ex.arrays['states/points'])} states of {len(online.taken)} presses in {out}" \
        + missed


async def _session(cfg: SessionConfig, part: Path, params: LiveParams, rrd: Path | None
                   ) -> LiveSummary:
    """Connect, check, calibrate, then stream into the journal until the session ends."""
    stream = Stream(params.host, params.port, params.timeout_s)
    xml = await stream.connect()
    try:
        layout = live_layout(parse_parameters(xml, stream.source), cfg)
        tip = tip_model(cfg, layout, params.calibration, SyncParams())
        model = None if params.model is None else \
            LiveModel(params.model, list(cfg.mocap.phantom_markers))
    except BadInput:
        await stream.close()
        raise
    part.parent.mkdir(parents=True, exist_ok=True)
    journal = Journal(part, _header(layout))
    with atomic_output(rrd) if rrd is not None else contextlib.nullcontext() as tmp:
        view = None if tmp is None else LiveView(tmp, len(cfg.mocap.phantom_markers),
                                                 params.spawn, params.serve,
                                                 model is not None)
        summary = await _stream(stream, layout, cfg, tip, journal, view, params, model)
        if view is not None:
            view.close()
    summary.rrd = rrd
    return summary


async def _stream(stream: Stream, layout: LiveLayout, cfg: SessionConfig, tip: TipModel,
                  journal: Journal, view: LiveView | None, params: LiveParams,
                  model: LiveModel | None) -> LiveSummary:
    """Every frame into the journal and the monitor until the stream ends."""
    recorder = Recorder(layout, journal)
    monitor = Monitor(layout, cfg, tip, view, model=model)
    latency: list[float] = []
    refused: list[BadInput] = []
    if view is not None:
        view.note(0, f"connected to {stream.source}: {len(layout.labels)} markers at "
                     f"{layout.rate_hz:g} Hz, force on {layout.device.name} at "
                     f"{layout.device.rate_hz:g} Hz; tip from {tip.source}")

    def on_frame(data: bytes) -> None:
        tic = time.perf_counter()
        try:
            frame = decode_frame(data, layout.device.device_id, layout.device.component)
            got = recorder.add(frame)
            if got is not None:
                monitor.frame(frame, got[0], got[1])
        except ValueError as e:
            refused.append(BadInput(stream.source, f"a damaged frame after frame "
                                                   f"{recorder.last_number} ({e})"))
            current[0].stop("a damaged frame")
        except BadInput as e:
            refused.append(e)
            current[0].stop("a frame refused")
        latency.append(time.perf_counter() - tic)

    current = [stream]
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, lambda s=sig: current[0].stop(
            f"stopped by {signal.Signals(s).name}"))
    start = time.perf_counter()
    try:
        while True:
            left = None if params.duration_s is None else \
                params.duration_s - (time.perf_counter() - start)
            await current[0].run(on_frame, left, layout.device.component)
            if not (current[0].lost and params.reconnect_s > 0 and not refused):
                break
            try:
                again = await _reconnect(current[0], layout, cfg, params, view, recorder)
            except BadInput as e:
                refused.append(e)
                break
            if again is None:
                break
            current[0] = again
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
        await current[0].close()
        recorder.flush()
        journal.close()
    stream = current[0]
    monitor.finish(recorder.last_time_ns)
    if view is not None:
        view.note(recorder.last_time_ns, f"ended: {stream.ended}")
    if stream.lost and not refused:
        again = f" (no answer for --reconnect {params.reconnect_s:g} s)" \
            if params.reconnect_s > 0 else ""
        refused.append(BadInput(stream.source, f"the connection was lost after frame "
                                               f"{recorder.counts.frames} of this session"
                                               f"{again}: session.mcap holds every frame up "
                                               "to it"))
    online = monitor.states
    return LiveSummary(stream.source, recorder.counts, stream.ended or "?", Path(), None,
                       time.perf_counter() - start, np.asarray(latency) * 1e3,
                       refused[0] if refused else None,
                       [] if online is None else coverage(online.taken),
                       0 if monitor.presses is None else monitor.presses.presses, online=online)


async def _reconnect(lost: Stream, layout: LiveLayout, cfg: SessionConfig, params: LiveParams,
                     view: LiveView | None, recorder: Recorder) -> Stream | None:
    """A new connection to the same server within ``params.reconnect_s``, streaming the same
    capture (the same parameters, else refused): the frames it sends again are dropped, the
    rest go on into the same journal. None when nothing answers in time."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + params.reconnect_s
    if view is not None:
        view.note(recorder.last_time_ns, f"{lost.ended}: reconnecting (up to "
                                         f"{params.reconnect_s:g} s)", rr.TextLogLevel.WARN)
    while loop.time() < deadline:
        stream = Stream(params.host, params.port, min(params.timeout_s,
                                                      max(deadline - loop.time(), 0.1)))
        try:
            xml = await stream.connect()
        except BadInput:
            await asyncio.sleep(RETRY_S)
            continue
        again = live_layout(parse_parameters(xml, stream.source), cfg)
        if (again.labels, again.rate_hz, again.device) != \
                (layout.labels, layout.rate_hz, layout.device):
            await stream.close()
            raise BadInput(stream.source, "reconnected, but QTM now streams another capture "
                                          f"(its markers, rate or {layout.device.what} "
                                          "changed): session.mcap holds the frames before")
        recorder.resuming = True
        if view is not None:
            view.note(recorder.last_time_ns, f"reconnected to {stream.source}: frames up to "
                                             f"{recorder.last_number} are not recorded twice")
        return stream
    return None


def _finish(part: Path, mcap: Path, cfg: SessionConfig, params: LiveParams) -> None:
    """The journal as ``session.mcap`` in ingest's layout, with its provenance; the journal
    removed once the MCAP is in place."""
    content = read_journal(part)
    layout = _layout(content.header, cfg)
    raw = raw_session(content.streams, layout, cfg)
    prov = make_provenance("live", asdict(params), session_inputs(cfg), SCHEMA, VERSION)
    write_raw_mcap(mcap, replace(raw, provenance=prov), {})
    part.unlink()


def raw_session(streams: dict[str, tuple[np.ndarray, np.ndarray]], layout: LiveLayout,
                cfg: SessionConfig) -> RawSession:
    """The journal's streams as ingest's raw session of the live capture: every marker QTM
    sent, the force converted as ingest converts an analog or force-plate export, the
    session's calibration and pivot recording."""
    t_m, v_m = streams[MARKERS]
    t_a, v_a = streams[FORCE]
    markers = MarkerSeries(source=layout.source, time_ns=t_m, labels=list(layout.labels),
                           positions=v_m.reshape(len(t_m), len(layout.labels), 3),
                           rate_hz=layout.rate_hz)
    force = replace(to_force(layout, v_a, cfg), time_ns=t_a)
    return RawSession(
        name=cfg.name, markers=markers, force=force,
        phantom_markers=list(cfg.mocap.phantom_markers),
        indenter_markers=list(cfg.mocap.indenter_markers), calibration=layout.calibration,
        pivot=read_mocap(cfg.pivot_file) if cfg.pivot_file is not None else None,
        phantom=cfg.phantom.as_json())


def _header(layout: LiveLayout) -> dict:
    """The journal's first record: what a reader needs to rebuild the layout."""
    return {"source": layout.source, "rate_hz": layout.rate_hz, "labels": layout.labels,
            "device": device_json(layout.device), "channels": layout.device.labels}


def _layout(header: dict, cfg: SessionConfig) -> LiveLayout:
    """The layout a journal's header records, with the session's calibration."""
    calibration = read_ati_cal(cfg.force.calibration) if cfg.force.calibration else None
    return LiveLayout(header["source"], float(header["rate_hz"]), list(header["labels"]),
                      device_from_json(header["device"]), calibration)

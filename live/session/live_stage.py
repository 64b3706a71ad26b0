"""The live runner: a session folder and QTM's real-time stream in; the session's MCAP, its
states and its recording out, written as the frames arrive.

Before the first frame: ``session.toml`` is read, QTM's parameters are held against it
(:mod:`live.session.layout`), the tip is calibrated (:mod:`live.session.calibration`) and QTM
starts streaming; any of them that cannot be trusted is refused in one line, the connection is
closed, and nothing is written. Then every frame goes into the journal (``session.mcap.part``,
:mod:`live.session.journal`) and to the monitor and view (:mod:`live.session.streaming`) until
``--duration``, Ctrl-C (or SIGTERM), QTM's end of the recording, a lost connection or a silent
server. However it ended, the journal then becomes ``LIVE_DIR/session.mcap`` in ingest's layout
(``phantom.raw_mcap``; ``pipeline sync`` runs on it as on an ingested file), with its
provenance, and the journal is removed; the recording is renamed into place beside it. A
damaged packet, a frame that contradicts the parameters, a lost connection or a reconnection to
another capture ends the session the same way and is then refused in one line (exit 2): what
arrived before it is kept, and no states are written.
"""

from __future__ import annotations

import asyncio
import contextlib
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from core.atomic import atomic_output
from core.errors import BadInput
from core.provenance import make_provenance
from core.series import MarkerSeries, RawSession
from core.text import count
from data_schema.raw_mcap import SCHEMA, VERSION
from data_schema.session import SessionConfig, read_session
from data_schema.states import STATES
from extract.extract import extract
from extract.extract_stage import write_states
from ingest.ati_cal import read_ati_cal
from ingest.detect import read_mocap
from ingest.ingest_params import IngestParams
from ingest.ingest_stage import session_inputs
from ingest.mcap_io import write_raw_mcap
from live.protocol.parameters import device_from_json, device_json
from live.session.calibration import tip_model
from live.session.journal import FORCE, MARKERS, Journal, JournalContent, read_journal
from live.session.layout import LiveLayout, to_force
from live.session.live_params import LiveParams
from live.session.live_view import LiveView
from live.session.model import LiveModel
from live.session.monitor import Monitor
from live.session.recorder import FLUSH_S, Counts, Recorder
from live.session.states import OnlineStates, PlaceCoverage, coverage
from live.session.streaming import Link, Streamed, Streaming
from sync.sync_params import SyncParams

MCAP_NAME = "session.mcap"
RRD_NAME = "session.rrd"
STATES_NAME = "states.h5"         # the states taken online


@dataclass(frozen=True)
class LiveSummary:
    """What a live session received, how it ended, how long each frame's work took, and what
    was seen of its presses."""

    source: str
    counts: Counts
    ended: str
    mcap: Path
    rrd: Path | None
    seconds: float
    latency_ms: np.ndarray
    locations: list[PlaceCoverage]             # pressed, as seen live
    presses: int
    states: str                           # what became of the session's states
    model_refused: int                    # presses the model gave no answer for


@dataclass(frozen=True)
class _Recorded:
    """What streaming left: how it went, what arrived, and the monitor's presses and states."""

    streamed: Streamed
    counts: Counts
    monitor: Monitor


def run_live(inputs: Path, out: Path, params: LiveParams | None = None,
             rrd: Path | None = None) -> LiveSummary:
    """Record the live session of the session folder ``inputs`` into the folder ``out``
    (``session.mcap``), with its recording ``rrd`` (None: none). A session refused mid-stream
    is bad input, raised once ``session.mcap`` holds every frame it received."""
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
    fresh = not Path(out).exists()
    got = asyncio.run(_record(cfg, part, params, rrd))
    s, m, frames = got.streamed, got.monitor, got.counts.frames
    if frames == 0:                  # refused at its first frame, or stopped before it
        _discard(part, rrd, Path(out) if fresh else None)
        raise _said(s.refusal or BadInput(m.layout.source, f"{s.ended}"), frames)
    _finish(read_journal(part), part, mcap, cfg, params)
    if s.refusal is not None:
        raise _said(s.refusal, frames)
    online = m.states
    return LiveSummary(
        source=m.layout.source, counts=got.counts, ended=s.ended, mcap=mcap, rrd=rrd,
        seconds=s.seconds, latency_ms=s.latency_ms,
        locations=[] if online is None else coverage(online.taken),
        presses=0 if m.presses is None else m.presses.presses,
        states=_states(online, mcap, params) if params.states and online is not None else "",
        model_refused=m.model_refused)


def _said(refusal: BadInput, frames: int) -> BadInput:
    """The refusal that ended a session, with what became of the ``frames`` it received."""
    kept = f"session.mcap holds the {count(frames, 'frame')} received before it" if frames \
        else "no frame was recorded, nothing written"
    return BadInput(refusal.path, f"{refusal.what}: {kept}", refusal.where)


def _discard(part: Path, rrd: Path | None, folder: Path | None) -> None:
    """A session that recorded no frame leaves nothing: its journal, its recording and the
    ``folder`` it made (None: one that was there before)."""
    part.unlink()
    if rrd is not None:
        rrd.unlink(missing_ok=True)
    if folder is not None:
        with contextlib.suppress(OSError):      # not empty: something else is in it
            folder.rmdir()


def _recover(part: Path, mcap: Path, cfg: SessionConfig, params: LiveParams) -> LiveSummary:
    """The journal a killed session left (``session.mcap.part``), every complete block of it,
    finished as ``session.mcap``; nothing is streamed. Its end says whether the journal was
    complete and how much was cut."""
    if not part.is_file():
        raise BadInput(part, "no journal of a killed session here: nothing to recover")
    if mcap.exists():
        raise BadInput(mcap, "exists: the session was finished already")
    content = read_journal(part)
    _finish(content, part, mcap, cfg, params)
    frames, samples = (len(content.streams[k][0]) for k in (MARKERS, FORCE))
    return LiveSummary(content.header["source"], Counts(frames, 0, samples),
                       _recovered(content), mcap, None, 0.0, np.empty(0), [], 0, "", 0)


def _recovered(content: JournalContent) -> str:
    """How a recovered journal ended, in words: complete, or cut short and by how much."""
    if content.complete:
        return (f"recovered from a complete journal ({content.blocks} blocks: its session "
                "closed it, and ended before it became session.mcap)")
    return (f"recovered from a journal cut short ({content.blocks} whole blocks kept, "
            f"{content.cut_bytes} bytes of a block cut short dropped; what had not reached "
            f"the journal, at most its last {FLUSH_S:g} s of frames, is lost)")


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
    missed += f" ({len(online.touched)} presses left out: a hole in the stream touches them)" \
        if online.touched else ""
    return f"{len(ex.arrays['states/points'])} states of {len(online.taken)} presses in {out}" \
        + missed


async def _record(cfg: SessionConfig, part: Path, params: LiveParams, rrd: Path | None
                  ) -> _Recorded:
    """Connect, check, calibrate, start the stream, then stream into the journal until the
    session ends; the connection closed however it ends."""
    link = Link(params, cfg)
    try:
        layout = await link.open()
        tip = tip_model(cfg, layout, params.calibration, SyncParams())
        model = None if params.model is None else \
            LiveModel(params.model, list(cfg.mocap.phantom_markers))
        await link.start()
        part.parent.mkdir(parents=True, exist_ok=True)
        journal = Journal(part, _header(layout))
        recorder = Recorder(layout, journal)
        try:
            with atomic_output(rrd) if rrd is not None else contextlib.nullcontext() as tmp:
                view = None if tmp is None else LiveView(tmp, len(cfg.mocap.phantom_markers),
                                                         params.spawn, params.serve,
                                                         model is not None)
                if view is not None:
                    view.note(0, f"connected to {layout.source}: {len(layout.labels)} markers "
                                 f"at {layout.rate_hz:g} Hz, force on {layout.device.name} at "
                                 f"{layout.device.rate_hz:g} Hz; tip from {tip.source}")
                monitor = Monitor(layout, cfg, tip, view, model=model)
                streamed = await Streaming(link, recorder, monitor, view).run()
                if view is not None:
                    view.close()
        finally:
            recorder.flush()
            journal.close()
    finally:
        await link.close()
    return _Recorded(streamed, recorder.counts, monitor)


def _finish(content: JournalContent, part: Path, mcap: Path, cfg: SessionConfig,
            params: LiveParams) -> None:
    """The journal's ``content`` as ``session.mcap`` in ingest's layout (and its default
    compression), with its provenance;
    the journal (``part``) removed once the MCAP is in place."""
    layout = _layout(content.header, cfg)
    raw = raw_session(content.streams, layout, cfg)
    prov = make_provenance("live", asdict(params), session_inputs(cfg), SCHEMA, VERSION)
    write_raw_mcap(mcap, replace(raw, provenance=prov), {}, IngestParams().compression)
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

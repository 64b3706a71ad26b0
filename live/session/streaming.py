"""A live session's stream: its connection to QTM (:class:`Link`: the one that stands now, held
against the session, replaced on a reconnection, closed however the session ends), and every
frame through the recorder and the monitor until the stream ends (:class:`Streaming`).

What ends a session, and how it is said:

- QTM's end of the recording, ``--duration``, ``--timeout`` seconds of silence, Ctrl-C or
  SIGTERM: the normal end, in words (:attr:`Streamed.ended`);
- a damaged packet, a frame that contradicts the parameters, a force that does not start
  unloaded, a connection lost (and not taken up again within ``--reconnect``), a reconnection
  to another capture: :attr:`Streamed.refusal`, the one line the runner raises once the MCAP
  holds every frame received (with what became of them);
- the model refusing a press is no end: the monitor warns and the session goes on.
"""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass

import numpy as np
import rerun as rr

from core.errors import BadInput
from data_schema.session import SessionConfig
from live.protocol.address import source_name
from live.protocol.client import Connection, Ending, Frame, connect
from live.protocol.parameters import parse_parameters
from live.session.layout import LiveLayout, live_layout
from live.session.live_params import LiveParams
from live.session.live_view import LiveView
from live.session.monitor import Monitor
from live.session.recorder import Recorder
from live.session.stop_signals import stopping_on_signals

RETRY_S = 0.5                     # between attempts to reconnect
MIN_TRY_S = 0.1                   # the shortest wait for an answer while reconnecting


class Link:
    """The session's connection to QTM: :attr:`connection` is the one that stands now (None
    before :meth:`open` and after :meth:`close`); whatever fails, :meth:`close` closes it."""

    def __init__(self, params: LiveParams, cfg: SessionConfig) -> None:
        self.params, self.cfg = params, cfg
        self.source = source_name(params.host, params.port)
        self.connection: Connection | None = None
        self.layout: LiveLayout | None = None
        self._stopped = False

    async def open(self) -> LiveLayout:
        """Connect, and hold QTM's parameters against the session: bad input where no
        server answers, it refuses, or its capture is not the session's."""
        self.layout = self._layout(await self._connect(self.params.timeout_s))
        return self.layout

    async def start(self) -> None:
        """Ask for the frames of the session's markers and force device."""
        await self.standing().start(self._opened().device)

    def standing(self) -> Connection:
        """The connection that stands now."""
        if self.connection is None:
            raise RuntimeError("no connection stands: open the link first")
        return self.connection

    def _opened(self) -> LiveLayout:
        """The session's streams, known once the link opened."""
        if self.layout is None:
            raise RuntimeError("the session's layout is unknown: open the link first")
        return self.layout

    async def reconnect(self) -> bool:
        """After a lost connection: connect again within ``--reconnect`` seconds to a server
        that streams the same capture, and start its stream; False where none answers in
        time (or the session was stopped meanwhile); bad input where it streams another
        capture, or will not stream."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.params.reconnect_s
        await self.close()
        while not self._stopped and loop.time() < deadline:
            try:
                xml = await self._connect(min(self.params.timeout_s,
                                              max(deadline - loop.time(), MIN_TRY_S)))
            except BadInput:                # nothing answers yet: QTM restarting, a cable
                await self.close()
                await asyncio.sleep(RETRY_S)
                continue
            again, before = self._layout(xml), self._opened()
            if (again.labels, again.rate_hz, again.device) != \
                    (before.labels, before.rate_hz, before.device):
                raise BadInput(again.source, "reconnected, but QTM now streams another "
                                             f"capture (its markers, rate or "
                                             f"{before.device.what} changed)")
            if self._stopped:               # stopped while connecting: no stream started
                await self.close()
                return False
            await self.start()
            if self._stopped:
                await self.close()
                return False
            return True
        return False

    def stop(self, why: str) -> None:
        """End the stream now standing (and any reconnection under way)."""
        self._stopped = True
        if self.connection is not None:
            self.connection.stop(why)

    async def close(self) -> None:
        """Close the connection now standing, if any."""
        connection, self.connection = self.connection, None
        if connection is not None:
            await connection.close()

    async def _connect(self, timeout_s: float) -> str:
        """Connect (the connection closed by :meth:`close`, whatever fails next): the
        parameters document it gave."""
        self.connection = await connect(self.params.host, self.params.port, timeout_s)
        return await self.connection.parameters()

    def _layout(self, xml: str) -> LiveLayout:
        """The session's streams in the capture ``xml`` describes."""
        return live_layout(parse_parameters(xml, self.source), self.cfg)


@dataclass(frozen=True)
class Streamed:
    """How a session's stream went: why it ended, what ends it as bad input (None: nothing),
    how long it ran and each frame's work (ms)."""

    ended: str
    refusal: BadInput | None
    seconds: float
    latency_ms: np.ndarray


class Streaming:
    """Every frame of the session into the recorder (the journal) and the monitor (the view,
    the presses, the states), across reconnections, until the stream ends."""

    def __init__(self, link: Link, recorder: Recorder, monitor: Monitor,
                 view: LiveView | None) -> None:
        self.link, self.recorder, self.monitor, self.view = link, recorder, monitor, view
        self.params = link.params
        self._refusal: BadInput | None = None
        self._stopped: str | None = None
        self._latency: list[float] = []

    async def run(self) -> Streamed:
        """Stream until the session ends (Ctrl-C and SIGTERM stop it): how it went."""
        start = time.perf_counter()
        d = self.params.duration_s
        with stopping_on_signals(self.stop):
            while True:
                left = None if d is None else d - (time.perf_counter() - start)
                ending = await self.link.standing().run(self.on_frame, left)
                if ending.damage is not None:
                    n = self.recorder.last_number
                    where = "before its first frame" if n is None else f"after frame {n}"
                    self._refuse(BadInput(self.link.source, f"a damaged packet {where} "
                                                            f"({ending.damage})"))
                if not ending.lost or self._refusal is not None or \
                        not await self._reconnected(ending):
                    break
        self.monitor.finish(self.recorder.last_time_ns)
        ended = self._stopped or ending.why
        if self.view is not None:
            self.view.note(self.recorder.last_time_ns, f"ended: {ended}")
        return Streamed(ended, self._refusal, time.perf_counter() - start,
                        np.asarray(self._latency) * 1e3)

    def on_frame(self, frame: Frame) -> None:
        """One frame: into the journal, then to the monitor; a frame that contradicts the
        parameters, or a force that does not start unloaded, ends the session."""
        tic = time.perf_counter()
        try:
            got = self.recorder.add(frame)
            if got is not None:
                self.monitor.frame(frame, got[0], got[1])
        except BadInput as e:
            self._refuse(e)
            return
        self._latency.append(time.perf_counter() - tic)

    def stop(self, why: str) -> None:
        """End the session (Ctrl-C, SIGTERM): every frame received is kept."""
        self._stopped = self._stopped or why
        self.link.stop(why)

    async def _reconnected(self, lost: Ending) -> bool:
        """Whether the lost connection was taken up again (``--reconnect``); where not, the
        session ends, said as bad input unless it was stopped meanwhile."""
        s = self.params.reconnect_s
        if s > 0:
            self._note(f"{lost.why}: reconnecting (up to {s:g} s)", rr.TextLogLevel.WARN)
            try:
                if await self.link.reconnect():
                    self.recorder.resuming = True
                    self._note(f"reconnected to {self.link.source}: frames up to "
                               f"{self.recorder.last_number} are not recorded twice")
                    return True
            except BadInput as e:
                self._refuse(e)
                return False
        if self._stopped is None:
            again = f" (no answer for --reconnect {s:g} s)" if s > 0 else ""
            self._refuse(BadInput(self.link.source, f"the connection was lost after frame "
                                                    f"{self.recorder.counts.frames} of this "
                                                    f"session{again}"))
        return False

    def _refuse(self, refusal: BadInput) -> None:
        """The session ends, and is refused in one line once its MCAP is written (the first
        refusal is the one said)."""
        self._refusal = self._refusal or refusal
        self.link.stop("a frame refused")

    def _note(self, text: str, level: rr.TextLogLevel = rr.TextLogLevel.INFO) -> None:
        if self.view is not None:
            self.view.note(self.recorder.last_time_ns, text, level)

"""Each frame as it arrives, turned into what the operator watches: the session's markers, the
tip (fitted where the view draws the scene), the tared force and its flags, handed to the live
view.

The force's channels (an analog board's, or a force plate's force and moment, already N and
N m) go to SI units by the same affine map ingest applies to the export
(:func:`live.session.layout.si_map`, measured once from :func:`live.session.layout.to_force`); its
bias comes from the unloaded start (:func:`live.session.calibration.force_tare`) once
:data:`calib.force_tare.TARE_S` seconds have arrived, and the samples before it are shown
then. By sync's rules, frame by frame, a gauge on the amplifier's rail
(:func:`sync.force_conditioning.at_rails`) is flagged saturated and a wrench beyond the
sensor's rating (:func:`sync.force_conditioning.beyond_rating`, where a .cal states one) over
range (the flat tops sync finds too need a whole recording's extremes); a wrench is tared as
sync tares it, less its bias. With a model, its answer is drawn beside the markers while a
press goes on; a press the model refuses is one warning line (stderr and the status log) and
goes on without it.
"""

from __future__ import annotations

import warnings

import numpy as np

from calib.force_tare import TARE_S, Tare
from core.progress import warn
from data_schema.session import SessionConfig
from extract.phantom_frame import to_phantom_frame
from live.protocol.client import Frame
from live.session.calibration import TipModel, force_tare, wrench
from live.session.layout import LiveLayout, si_map
from live.session.live_view import LiveView
from live.session.model import LiveModel, ModelRefusal
from live.session.presses import PressTracker
from live.session.states import Conditioning, History, LivePress, OnlineStates, Surface
from sync.force_conditioning import at_rails, beyond_rating, contact_level, noise_level, rails
from sync.presses import PressRule
from sync.surface import rest_of
from sync.sync_params import SyncParams


class Monitor:
    """The per-frame work of a live session, and the view it feeds (``view`` None: the work
    alone, as a benchmark's dry run)."""

    def __init__(self, layout: LiveLayout, cfg: SessionConfig, tip: TipModel,
                 view: LiveView | None, params: SyncParams | None = None,
                 model: LiveModel | None = None) -> None:
        names = cfg.mocap.phantom_markers + cfg.mocap.indenter_markers
        self.index = np.array([layout.labels.index(n) for n in names])
        self.phantom = len(cfg.mocap.phantom_markers)
        self.layout, self.tip, self.view, self.model = layout, tip, view, model
        self.cfg = cfg
        self.params = params or SyncParams()
        self._si = si_map(layout, cfg)
        self.kind = cfg.force.kind
        self._rails = rails(cfg.force.kind, layout.calibration)
        self.tare: Tare | None = None
        self.presses: PressTracker | None = None       # once the tare gives the contact
        self.states: OnlineStates | None = None        # ... and the phantom's rest
        self.history = History(len(names), len(cfg.force.channels))
        self._early: list[tuple[np.ndarray, np.ndarray]] = []   # samples before the tare
        self._early_samples = 0
        self._rest: list[np.ndarray] = []      # markers before the tare: the phantom's rest
        self._force_now = 0.0
        self._started = False                  # a contact began: the next frame is its start
        self.saturated = self.over_range = 0
        self.model_refused = 0                 # presses the model gave no answer for

    def frame(self, frame: Frame, time_ns: int, sample_ns: np.ndarray | None) -> None:
        """One frame: its scene, and its force samples where it carries any."""
        markers = frame.markers[self.index]
        self.history.add_frame(time_ns, markers)
        if self.tare is None:
            self._rest.append(markers)
        drawn = self.view is not None and self.view.due(time_ns)
        contact = self.presses is not None and self.presses.in_contact
        tip = None
        if drawn or self._started:                     # the tip where it is shown or used
            tip = self.tip.tips(markers[None, self.phantom:], self.params)[0]
        if self._started and self.model is not None and tip is not None:
            self.model.start(markers[:self.phantom], tip, self._force_now)
        self._started = False
        if self.view is not None:
            self.view.frame(time_ns, markers, tip if drawn else None)
            if drawn and contact and self.model is not None and tip is not None:
                self._answer(self.model, self.view, time_ns, markers[:self.phantom], tip)
        if frame.force is not None:
            if sample_ns is None:
                raise ValueError("a frame's force samples came without their times")
            self._force(sample_ns, self._si(frame.force))
        if self.states is not None:
            self._show(time_ns, self.states, self.states.poll(time_ns))

    def _answer(self, model: LiveModel, view: LiveView, time_ns: int, phantom: np.ndarray,
                tip: np.ndarray) -> None:
        """The model's answer for the press under way, drawn; its refusal a warning."""
        try:
            reading = model.at(phantom, tip, self._force_now)
        except ModelRefusal as e:
            self.model_refused += 1
            text = (f"the model refused the press under way at {time_ns * 1e-9:.2f} s ({e}): "
                    "no answer for it; the session goes on")
            warn(text)
            view.warning(time_ns, text)
            return
        if reading is not None:
            view.model(time_ns, reading)

    def finish(self, time_ns: int) -> None:
        """The session ended at ``time_ns``: the presses still to be taken, taken."""
        if self.states is not None:
            self._show(time_ns, self.states, self.states.finish(time_ns))

    def _show(self, time_ns: int, states: OnlineStates, taken: list[LivePress]) -> None:
        """The presses just taken and the notes not yet shown, to the view."""
        if self.view is not None:
            for press in taken:
                self.view.taken(time_ns, press, states)
            for note in states.notes:
                self.view.warning(time_ns, note)
        states.notes.clear()

    def _force(self, times: np.ndarray, values: np.ndarray) -> None:
        """Force samples in SI units: shown once the tare is known (the early ones then)."""
        if self.tare is None:
            early = self._early_force(times, values)
            if early is None:
                return
            times, values = early
            self._calibrated(force_tare(values, self.layout.device.rate_hz, self.layout.source),
                             int(times[-1]), values)
        tare, presses, states = self._ready()
        w = wrench(values, tare, self.layout)
        saturated = at_rails(values, self._rails)
        over = beyond_rating(w, self.layout.calibration)
        self.saturated += int(saturated.sum())
        self.over_range += int(over.sum())
        magnitude = np.linalg.norm(w[:, :3], axis=1)
        if self.view is not None:
            self.view.force(times, magnitude, saturated, over)
        self.history.add_force(times, values, saturated | over)
        self._force_now = float(magnitude[-1])
        was = presses.in_contact
        done = presses.add(times, magnitude)
        self._started = not was and presses.in_contact
        for press in done:
            states.ended(press)
            if self.view is not None:
                self.view.press(press)

    def _early_force(self, times: np.ndarray, values: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray] | None:
        """Samples before the tare, kept: all of them once :data:`TARE_S` seconds have
        arrived (None until then)."""
        self._early.append((times, values))
        self._early_samples += len(times)
        if self._early_samples < TARE_S * self.layout.device.rate_hz:
            return None
        early = (np.concatenate([t for t, _ in self._early]),
                 np.concatenate([v for _, v in self._early]))
        self._early = []
        return early

    def _ready(self) -> tuple[Tare, PressTracker, OnlineStates]:
        """The tare and what it makes possible: the presses and their states."""
        if self.tare is None or self.presses is None or self.states is None:
            raise RuntimeError("the force is read before its tare is known")
        return self.tare, self.presses, self.states

    def _calibrated(self, tare: Tare, time_ns: int, values: np.ndarray) -> None:
        """Once the tare is known: the contact level, the phantom's rest, the online states."""
        self.tare = tare
        w = wrench(values, tare, self.layout)
        noise = noise_level(w, tare)
        p = self.params
        contact = contact_level(p, noise)
        self.presses = PressTracker(self.layout.device.rate_hz, PressRule(p.detect_n, contact))
        surface = self._surface()
        self.states = OnlineStates(self.cfg, self.layout, self.tip, self.history, surface,
                                   Conditioning(tare, noise, contact), p)
        if self.model is not None:
            self.model.to_phantom = surface.transform
        curved = surface.rest.curved
        if self.view is not None and curved is not None:
            self.view.shape(curved.shape, curved.registration.to_shape)
        if self.view is not None:
            self.view.note(time_ns, f"force tared over its first "
                                    f"{tare.stop / self.layout.device.rate_hz:.2f} s "
                                    f"(unloaded start; noise {noise * 1e3:.1f} mN)")

    def _surface(self) -> Surface:
        """The phantom's rest surface and frame from the markers at rest before the tare: sync's
        rest plane (:func:`sync.surface.rest_of`) with extract's axes and origin, or a curved
        phantom's shape registered to the markers, its own frame."""
        frames = np.stack(self._rest)
        self._rest = []
        phantom, cluster = frames[:, :self.phantom], frames[:, self.phantom:]
        tips = self.tip.tips(cluster, self.params)
        names = list(self.cfg.mocap.phantom_markers)
        rest = rest_of(phantom, cluster, tips, names, self.cfg.phantom, self.layout.source)
        if rest.registration is not None:          # a curved phantom: its shape's frame
            return Surface(rest, rest.registration.to_shape)
        with warnings.catch_warnings():          # a marker never seen at rest: NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            still = np.nanmedian(phantom, axis=0)
        return Surface(rest, to_phantom_frame(still, names, rest.point, rest.normal,
                                              self.cfg.phantom))


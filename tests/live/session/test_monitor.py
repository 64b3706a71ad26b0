"""The live session's per-frame work (:class:`live.session.monitor.Monitor`), frame by frame on
a twin session whose force QTM's analog board samples (four presses at four places, seed 3),
against the twin's truth: the tare is the gauges' true bias, the tared force shown is the true
contact force, every force sample is shown once and in order (those before the tare once it is
known), the presses and their places are the truth's, a gauge on the amplifier's rail is
counted sample by sample, and a model that refuses a press is one warning for that press."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np
import pytest
from helpers.live_frames import LiveInputs, frames, live_inputs

from calib.force_tare import TARE_S
from live.session.model import ModelRefusal
from live.session.monitor import Monitor
from sync.force_conditioning import rails

DRAW_EVERY = 25        # the fake view draws every 25th frame (20 Hz at 500 Hz)


@dataclass
class RecordingView:
    """What the monitor hands the live view, kept."""

    frames: int = 0
    force_times: list[np.ndarray] = field(default_factory=list)
    magnitudes: list[np.ndarray] = field(default_factory=list)
    presses: int = 0
    warnings: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def due(self, time_ns: int) -> bool:
        self.frames += 1
        return self.frames % DRAW_EVERY == 0

    def frame(self, time_ns, markers, tip) -> None: ...

    def force(self, times, magnitude, saturated, over) -> None:
        self.force_times.append(times)
        self.magnitudes.append(magnitude)

    def press(self, press) -> None:
        self.presses += 1

    def taken(self, time_ns, press, states) -> None: ...

    def model(self, time_ns, reading) -> None: ...

    def warning(self, time_ns: int, text: str) -> None:
        self.warnings.append(text)

    def note(self, time_ns: int, text: str) -> None:
        self.notes.append(text)


class RefusingModel:
    """A model that refuses each press the first time it is asked, as a predictor refuses a
    surface far outside what it learned (:class:`live.session.model.LiveModel` then waits for
    the next press)."""

    def __init__(self) -> None:
        self.to_phantom: np.ndarray | None = None
        self.starts = 0
        self._armed = False

    def start(self, phantom: np.ndarray, tip: np.ndarray, force_n: float) -> None:
        self.starts += 1
        self._armed = True

    def at(self, phantom: np.ndarray, tip: np.ndarray, force_n: float) -> None:
        if self._armed:
            self._armed = False
            raise ModelRefusal("a surface far outside what it learned")


def _run(inputs: LiveInputs, view=None, model=None, spoil=None) -> Monitor:
    monitor = Monitor(inputs.layout, inputs.cfg, inputs.tip, view, model=model)
    last = 0
    for frame, time_ns, sample_ns in frames(inputs):
        if spoil is not None and frame.force is not None:
            spoil(frame.force, sample_ns)
        monitor.frame(frame, time_ns, sample_ns)
        last = time_ns
    monitor.finish(last)
    return monitor


@pytest.fixture(scope="module")
def inputs(twin_session: Path) -> LiveInputs:
    return live_inputs(twin_session)


@pytest.fixture(scope="module")
def watched(inputs: LiveInputs) -> tuple[Monitor, RecordingView, RefusingModel]:
    view, model = RecordingView(), RefusingModel()
    return _run(inputs, view, model), view, model


@pytest.fixture(scope="module")
def truth(twin_session: Path) -> dict[str, np.ndarray]:
    with h5py.File(twin_session / "truth.h5", "r") as f:
        return {k: f[k][()] for k in (
            "calibration/bias", "calibration/bias_drift", "calibration/matrix",
            "logger/time_s", "logger/tool_force", "mocap/time_s", "force/magnitude",
            "presses/location")}


def test_the_tare_is_the_gauges_true_bias_with_the_tool_s_weight(watched, truth) -> None:
    """The first TARE_S of the unloaded start, averaged: the gauges' true bias (with its creep
    over those samples) and what the tool's weight below the sensor adds, which the calibration
    matrix turns into that weight (``logger/tool_force``) to well within the Nano17's
    resolution (1/320 N)."""
    monitor, _, _ = watched
    tare = monitor.tare
    assert tare.stop - tare.start >= TARE_S * monitor.layout.device.rate_hz
    rows = slice(tare.start, tare.stop)
    bias = truth["calibration/bias"] + truth["calibration/bias_drift"] * \
        truth["logger/time_s"][rows].mean()
    weight = truth["calibration/matrix"] @ (tare.bias - bias)
    assert np.allclose(weight[:3], truth["logger/tool_force"][rows].mean(axis=0), atol=1e-3)
    assert np.abs(truth["logger/tool_force"][rows].mean(axis=0)).max() > 0.01   # it weighs


def test_every_force_sample_is_shown_once_in_order(watched, inputs) -> None:
    """Those before the tare are held and shown once it is known."""
    monitor, view, _ = watched
    times = np.concatenate(view.force_times)
    assert len(times) == inputs.source.force.values.shape[0]
    assert np.all(np.diff(times) > 0)


def test_the_force_shown_is_the_true_contact_force(watched, truth) -> None:
    """Tared with the session's start only (no re-tare live), the force at each frame is the
    truth's within a few tens of millinewtons (the Nano17's noise and the bias's creep)."""
    _, view, _ = watched
    t = np.concatenate(view.force_times) * 1e-9
    shown = np.interp(truth["mocap/time_s"], t, np.concatenate(view.magnitudes))
    error = np.abs(shown - truth["force/magnitude"])
    assert np.median(error) < 0.02 and np.percentile(error, 99) < 0.1, \
        (np.median(error), np.percentile(error, 99))
    assert truth["force/magnitude"].max() > 4.0          # the presses are real ones


def test_the_presses_and_their_places_are_the_truth_s(watched, truth) -> None:
    monitor, view, _ = watched
    places = truth["presses/location"]
    assert view.presses == len(places) == len(monitor.states.taken)
    found = [p.location for p in monitor.states.taken]
    # the same partition of presses into places (the ids are numbered as first pressed)
    assert [found.index(x) for x in found] == [list(places).index(x) for x in places]
    assert all(len(p.states.step) > 1 for p in monitor.states.taken)


def test_a_refused_press_is_one_warning_and_the_session_goes_on(watched, truth) -> None:
    monitor, view, model = watched
    presses = len(truth["presses/location"])
    assert model.starts == presses and monitor.model_refused == presses
    refused = [w for w in view.warnings if "the model refused" in w]
    assert len(refused) == presses and all("the session goes on" in w for w in refused)
    assert model.to_phantom is not None and model.to_phantom.shape == (4, 4)


def test_a_gauge_on_the_rail_is_counted_sample_by_sample(inputs) -> None:
    """Gauge 2 set on the amplifier's upper rail for 37 samples after the tare: 37 saturated
    samples, no more."""
    low, high = rails(inputs.cfg.force.kind, inputs.layout.calibration)
    start = int(3 * TARE_S * inputs.layout.device.rate_hz)     # well after the tare
    span = range(start, start + 37)
    t0 = {}

    def spoil(values: np.ndarray, sample_ns: np.ndarray) -> None:
        first = t0.setdefault("ns", int(sample_ns[0]))
        index = np.round((sample_ns - first) * 1e-9 * inputs.layout.device.rate_hz).astype(int)
        values[np.isin(index, span), 2] = high

    monitor = _run(inputs, spoil=spoil)
    assert monitor.saturated == len(span)
    assert low < 0 < high

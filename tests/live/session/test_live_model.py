"""The model beside the press under way (:mod:`live.session.model`), on a small model trained
on the dent data (its points named as a session's: the markers, then the tip): a run trained
on other markers is refused naming it; the answer does not depend on the lab frame (it is the
predictor's in the phantom frame, carried to the lab and back); no motion is no change, so the
answer's distance and force error are the measurement's own; a press the predictor refuses is
refused once and then left; nothing is answered before a press's start is known."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from helpers.cgnn_data import TINY, dent, write_dent_split, write_dent_states

from core.errors import BadInput
from live.session.model import LiveModel, ModelRefusal
from sync.sync import TIP
from train.inference.predictor import DEFAULT_REGION, Predictor
from train.training.train_params import TrainInputs, TrainOptions, TrainParams
from train.training.train_stage import run_train

MARKERS = [f"P{k:02d}" for k in range(48)]        # the dent file's points, the last the tip


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    """One epoch on the dent data whose last point is named the tip."""
    d = tmp_path_factory.mktemp("live_model")
    data, splits = d / "states.h5", d / "splits.json"
    write_dent_states(data)
    with h5py.File(data, "r+") as f:
        f.attrs["point_names"] = json.dumps([*MARKERS, TIP])
    write_dent_split(data, splits)
    run_train(TrainInputs(data, splits), d / "run",
              TrainParams(TrainOptions(epochs=1, batch=8), TINY, "cpu"))
    return d / "run"


def _turn(degrees: float, shift: tuple[float, float, float]) -> np.ndarray:
    """A lab -> phantom transform: a turn about z and a shift."""
    a = np.radians(degrees)
    t = np.eye(4)
    t[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    t[:3, 3] = shift
    return t


def _lab(transform: np.ndarray, points: np.ndarray) -> np.ndarray:
    inverse = np.linalg.inv(transform)
    return points @ inverse[:3, :3].T + inverse[:3, 3]


def _surface() -> np.ndarray:
    """The dent data's rest surface (48 markers, phantom frame) and a tip above its middle."""
    g = (np.arange(7) + 0.5) / 7 * 0.1
    rest = np.stack([*np.meshgrid(g, g), np.zeros((7, 7))], -1).reshape(-1, 3)
    return rest[:48]


def test_a_run_of_other_markers_is_refused_naming_it(run) -> None:
    with pytest.raises(BadInput) as e:
        LiveModel(run, [f"M{k}" for k in range(48)])
    assert e.value.path == str(run) and "another phantom's markers" in e.value.what
    LiveModel(run, MARKERS)


def test_nothing_is_answered_before_a_start_or_without_a_frame(run) -> None:
    model = LiveModel(run, MARKERS)
    tip = np.array([0.05, 0.05, 0.0])
    assert model.at(_surface(), tip, 1.0) is None                 # no start yet
    model.start(_surface(), tip, 0.0)                             # no frame (to_phantom) yet
    assert model.at(_surface(), tip, 1.0) is None
    model.to_phantom = np.eye(4)
    lost = _surface()
    lost[3] = np.nan
    model.start(lost, tip, 0.0)                                   # a marker unseen at start
    assert model.at(_surface(), tip, 1.0) is None
    model.start(_surface(), tip, 0.0)
    assert model.at(_surface(), np.full(3, np.nan), 1.0) is None  # no tip now


def test_the_answer_is_the_predictor_s_in_the_phantom_frame(run) -> None:
    """In a lab turned 30 degrees and shifted, the points predicted are the predictor's own
    answer in the phantom frame, carried to the lab; its distance to the markers measured
    counts those seen; its force error is the predicted change less the measured one."""
    to_phantom = _turn(30.0, (0.2, -0.1, 0.05))
    start = _surface()
    tip_start, tip_now = np.array([0.05, 0.05, 0.0]), np.array([0.05, 0.05, -3e-3])
    now = dent(np.vstack([start, tip_start]), tip_start[:2], 3e-3)[:48]
    now_lab = _lab(to_phantom, now)
    now_lab[5] = np.nan                                            # a marker lost now
    model = LiveModel(run, MARKERS)
    model.to_phantom = to_phantom
    model.start(_lab(to_phantom, start), _lab(to_phantom, tip_start), 0.4)
    reading = model.at(now_lab, _lab(to_phantom, tip_now), 1.9)
    points = np.vstack([start, tip_start]).astype(np.float32)
    want = Predictor.load(run).predict(points, np.r_[tip_start, tip_now].astype(np.float32),
                                       region=DEFAULT_REGION)
    np.testing.assert_allclose(reading.predicted, _lab(to_phantom, want.points[:-1]),
                               atol=1e-6)
    seen = np.isfinite(now_lab).all(axis=1)
    ld = np.linalg.norm(reading.predicted[seen] - now_lab[seen], axis=1).mean() * 1e3
    assert reading.ld_mm == pytest.approx(ld, rel=1e-6)
    assert reading.force_error_n == pytest.approx(want.dforce - 1.5, abs=1e-6)


def test_no_motion_is_no_change(run) -> None:
    """The tip where it started: the markers predicted where they were (the network's
    no-motion gate), so the distance is the markers' own motion and the force error minus the
    measured change."""
    to_phantom = _turn(-45.0, (0.0, 0.3, 0.0))
    start = _surface()
    tip = np.array([0.05, 0.05, 0.0])
    model = LiveModel(run, MARKERS)
    model.to_phantom = to_phantom
    model.start(_lab(to_phantom, start), _lab(to_phantom, tip), 0.0)
    moved = _lab(to_phantom, start + [0.0, 0.0, -1e-3])            # every marker 1 mm down
    reading = model.at(moved, _lab(to_phantom, tip), 0.25)
    np.testing.assert_allclose(reading.predicted, _lab(to_phantom, start), atol=1e-6)
    assert reading.ld_mm == pytest.approx(1.0, abs=1e-3)
    assert reading.force_error_n == pytest.approx(-0.25, abs=1e-9)


def test_a_press_the_predictor_refuses_is_refused_once(run) -> None:
    """A surface 17 m from anything trained on: one refusal in the predictor's words, then no
    answer until the next press starts."""
    model = LiveModel(run, MARKERS)
    model.to_phantom = np.eye(4)
    far = _surface() + [17.0, 0.0, 0.0]
    model.start(far, np.array([17.05, 0.05, 0.0]), 0.0)
    with pytest.raises(ModelRefusal, match="m from the training data"):
        model.at(far, np.array([17.05, 0.05, -2e-3]), 0.5)
    assert model.at(far, np.array([17.05, 0.05, -2e-3]), 0.5) is None
    model.start(_surface(), np.array([0.05, 0.05, 0.0]), 0.0)
    assert model.at(_surface(), np.array([0.05, 0.05, -2e-3]), 0.5) is not None

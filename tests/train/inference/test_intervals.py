"""The predictor's intervals: each point's radius and the force's interval are the table's
for the press (a table whose radii are known), on every backend and path, beside an unchanged
answer; a run's own validation presses, looked up, get the radii calibrated for them; a
checkpoint whose table was written before this version, and one without a table, load;
refused in one line where they cannot be given; said not to hold beyond the envelope; carried
by the exported ONNX file."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import h5py
import numpy as np
import onnx
import pytest
import torch
from helpers.cgnn_data import TINY, dent_fold
from helpers.interval_table import EDGE, FAR, HALF, NEAR, known_table, stored_table

from train import Predictor
from train.inference.export import export_onnx
from train.intervals.levels import level_index
from train.intervals.table import IntervalTable
from train.training.calibrate import residuals
from train.training.checkpoint import load_checkpoint, model_from
from train.training.fold_data import fold_examples
from train.training.train_params import TrainInputs, TrainOptions, TrainParams
from train.training.train_stage import run_train


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray, np.ndarray]:
    """A tiny model trained on the dent data until its force lies in the learned range:
    (run, a state's points, a press)."""
    d = tmp_path_factory.mktemp("intervals")
    data, splits = dent_fold(d, folds=1)
    run_train(TrainInputs(data, splits), d / "run",
              TrainParams(TrainOptions(epochs=4, batch=8, lr=1e-2), TINY, "cpu"))
    with h5py.File(data) as f:
        points, tip = f["states/points"][3], f["states/tip"][3]
    return d / "run", points, np.r_[tip, tip - [0, 0, 1e-3]].astype(np.float32)


def _expected(points: np.ndarray, cond: np.ndarray) -> np.ndarray:
    """The known radii: the press is vertical, so a point's distance from its path is the
    planar one where it lies within the press's height range."""
    planar = np.linalg.norm(points[:, :2] - cond[:2], axis=1)
    above = np.maximum(points[:, 2] - cond[2], 0) + np.maximum(cond[5] - points[:, 2], 0)
    return np.where(np.hypot(planar, above) < EDGE, NEAR, FAR)


@pytest.mark.parametrize("backend", ["torch", "onnx"])
@pytest.mark.parametrize("region", [None, 0.02])
def test_radii_and_force_interval_are_the_tables(run, backend: str, region: float | None
                                                 ) -> None:
    path, points, cond = run
    p = Predictor.load(path, backend=backend)
    p.intervals = known_table()
    for _ in range(2):                       # a new scene, then the known mesh's fast path
        answer = p.predict(points, cond, region=region, level=0.9)
        deformed, df, sure = answer.points, answer.dforce, answer.sure
        plain, plain_df = p.predict(points, cond, region=region)
        np.testing.assert_array_equal(deformed, plain)
        assert df == plain_df
        np.testing.assert_array_equal(sure.radius, _expected(points, cond))
        assert sure.force == pytest.approx((df - HALF, df + HALF))
        assert sure.holds and sure.level == 0.9
    force, (low, high) = p.predict_force(points, cond, level=0.8)
    assert (low, high) == pytest.approx((force - HALF, force + HALF))


def test_the_trained_radii_grow_with_the_level(run) -> None:
    path, points, cond = run
    p = Predictor.load(path)
    radii = [p.predict(points, cond, level=q).sure.radius for q in (0.5, 0.8, 0.9, 0.95)]
    assert all((b >= a).all() for a, b in zip(radii, radii[1:], strict=False))
    assert np.isfinite(radii[1]).all() and (radii[1] > 0).all()


def test_levels_and_absent_intervals_are_refused_in_one_line(run, tmp_path: Path) -> None:
    path, points, cond = run
    p = Predictor.load(path)
    for level in (0.0, 1.0, 1.5, -0.2, float("nan")):
        with pytest.raises(ValueError, match=r"^level must lie in \(0, 1\), got"):
            p.predict(points, cond, level=level)
    old = torch.load(path / "best.pt", weights_only=True)
    del old["intervals"]                     # a checkpoint from before intervals
    torch.save(old, tmp_path / "old.pt")
    before = Predictor.load(tmp_path / "old.pt")
    assert before.predict(points, cond).sure is None       # it still predicts
    for call in (before.predict, before.predict_force):
        with pytest.raises(ValueError, match="^intervals absent") as e:
            call(points, cond, level=0.9)
        assert "\n" not in str(e.value)


def test_beyond_the_envelope_the_intervals_do_not_hold(run) -> None:
    path, points, cond = run
    p = Predictor.load(path)
    deep = cond.copy()
    deep[5] -= 0.02                           # a press four times the longest learned
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sure = p.predict(points, deep, level=0.9).sure
    assert not sure.holds
    assert any("intervals do not hold" in str(w.message) for w in caught)
    with warnings.catch_warnings():
        warnings.simplefilter("error")       # inside: no warning, and they hold
        assert p.predict(points, cond, level=0.9).sure.holds


def test_the_onnx_file_carries_the_table(run, tmp_path: Path) -> None:
    path, _, _ = run
    export_onnx(path, tmp_path / "m.onnx")
    props = {p.key: p.value for p in onnx.load(str(tmp_path / "m.onnx")).metadata_props}
    table = IntervalTable.from_dict(json.loads(props["intervals"]))
    want = IntervalTable.from_dict(torch.load(path / "best.pt", weights_only=True)["intervals"])
    np.testing.assert_array_equal(table.points.width, want.points.width)
    assert table.points.edges == want.points.edges
    assert "level index" in props["intervals_lookup"]


def test_a_validation_press_looked_up_gets_its_calibrated_radius(run) -> None:
    """The run's table was calibrated on its validation presses: each of them, predicted
    with a level, gets for each point the radius the table gives the features calibration
    measured for it (many lie on a bin's edge: the dent's depths are whole millimetres), and
    the force's half-width for the press's."""
    path, _, _ = run
    p = Predictor.load(path)
    state = load_checkpoint(path / "best.pt")
    data, splits = path.parent / "states.h5", path.parent / "splits.json"
    states, _, val, _ = fold_examples(data, splits, TrainOptions(epochs=4, batch=8, lr=1e-2))
    r = residuals(*model_from(state), states, val)
    table, i = p.intervals, level_index(0.9)
    assert np.isin(r.force_features[:, 0], table.force.edges[0]).any()
    points, tips = states.points.numpy(), states.tip.numpy()
    for e, (s, t) in enumerate(val.tolist()):
        mine = r.point_example == e
        sure = p.predict(points[s], np.r_[tips[s], tips[t]], level=0.9).sure
        np.testing.assert_array_equal(sure.radius, table.radii(i, *r.point_features[mine].T))
        assert sure.force[1] - sure.force[0] == 2 * table.force.widths(i, *r.force_features[e])


def test_a_checkpoint_with_a_table_of_the_first_form_loads(run, tmp_path: Path) -> None:
    """``best.pt`` whose ``intervals`` were written by the first version (the form spelled
    out by hand in tests/train/intervals/test_table.py): its radii are what it says."""
    path, points, cond = run
    old = torch.load(path / "best.pt", weights_only=True)
    old["intervals"] = stored_table()
    torch.save(old, tmp_path / "old.pt")
    sure = Predictor.load(tmp_path / "old.pt").predict(points, cond, level=0.9).sure
    np.testing.assert_array_equal(sure.radius, np.where(_expected(points, cond) == NEAR,
                                                        1e-3, 1e-4))

"""The predictor's intervals: each point's radius and the force's interval are the table's
for the press (a table whose radii are known), on every backend and path, beside an unchanged
answer; refused in one line where they cannot be given; said not to hold beyond the envelope;
carried by the exported ONNX file."""

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
from helpers.interval_table import EDGE, FAR, HALF, NEAR, known_table

from train import Predictor
from train.inference.export import export_onnx
from train.model.conformal import IntervalTable
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
        deformed, df, sure = p.predict(points, cond, region=region, level=0.9)
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
    radii = [p.predict(points, cond, level=q)[2].radius for q in (0.5, 0.8, 0.9, 0.95)]
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
    assert len(before.predict(points, cond)) == 2          # it still predicts
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
        *_, sure = p.predict(points, deep, level=0.9)
    assert not sure.holds
    assert any("intervals do not hold" in str(w.message) for w in caught)
    with warnings.catch_warnings():
        warnings.simplefilter("error")       # inside: no warning, and they hold
        assert p.predict(points, cond, level=0.9)[2].holds


def test_the_onnx_file_carries_the_table(run, tmp_path: Path) -> None:
    path, _, _ = run
    export_onnx(path, tmp_path / "m.onnx")
    props = {p.key: p.value for p in onnx.load(str(tmp_path / "m.onnx")).metadata_props}
    table = IntervalTable.from_dict(json.loads(props["intervals"]))
    want = IntervalTable.from_dict(torch.load(path / "best.pt", weights_only=True)["intervals"])
    np.testing.assert_array_equal(table.points.width, want.points.width)
    assert table.points.edges == want.points.edges
    assert "level index" in props["intervals_lookup"]

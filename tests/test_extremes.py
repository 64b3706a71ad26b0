"""Numerical stability at the extremes: wrong units, tiny and limit forces, long recordings,
degenerate splits and training sets smaller than a batch.

(The MSM at its time-step limit is tested in test_msm.py: just below the computed limit it
settles, just above it stops with a clear error.)
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np
import pytest
import torch
from click.testing import CliRunner
from helpers.cgnn_data import write_dent_split, write_dent_states

from core.errors import BadInput
from core.series import frame_times_ns, time_to_ns
from data_schema.states import validate_states
from pipeline.cli import cli
from sync.force_conditioning import beyond_rating
from train.data import load_manifest, role_examples
from train.evaluation.run_errors import example_errors, load_run
from train.model.config import CGNNConfig
from train.training.checkpoint import load_checkpoint
from train.training.train_params import TrainInputs, TrainOptions, TrainParams
from train.training.train_stage import run_train

SMALL = CGNNConfig(edge_widths=((16, 16),) * 3, disp_widths=(32,), force_widths=(16, 8, 8))
NANO17_MAX = np.array([25.0, 25.0, 35.0, 0.25, 0.25, 0.25])      # SI-25-0.25, N and N m


def _dent(tmp_path: Path, scale: dict[str, float] | None = None, manifest: bool = True,
          **kw) -> tuple[Path, Path]:
    """A dent states file (datasets multiplied by ``scale``) and its 2-fold manifest."""
    data = tmp_path / "states.h5"
    write_dent_states(data, **kw)
    with h5py.File(data, "r+") as f:
        for name, factor in (scale or {}).items():
            f[name][...] = f[name][()] * factor
    splits = tmp_path / "splits.json"
    if manifest:
        write_dent_split(data, splits)
    return data, splits


@pytest.mark.parametrize(("name", "what"), [("states/points", "millimetres"),
                                            ("states/tip", "millimetres"),
                                            ("states/force", "millinewtons")])
def test_states_in_other_units_are_refused_not_learned(tmp_path, name, what) -> None:
    data, _ = _dent(tmp_path, {name: 1000.0}, manifest=False)
    with pytest.raises(BadInput, match=what):
        validate_states(data)
    res = CliRunner().invoke(cli, ["split", str(data), "--out", str(tmp_path / "s.json")])
    assert res.exit_code == 2 and what in res.output and "Traceback" not in res.output
    assert len(res.output.strip().splitlines()) == 1 and not (tmp_path / "s.json").exists()


def test_forces_near_zero_train_to_finite_small_predictions(tmp_path) -> None:
    """Force changes of a micronewton: the normaliser's scale follows them down, nothing
    overflows, and the predicted changes stay of the truth's order, not of a newton."""
    data, splits = _dent(tmp_path, {"states/force": 2e-6})       # 0.5 N per level -> 1 uN
    run_train(TrainInputs(data, splits), tmp_path / "run",
              TrainParams(TrainOptions(epochs=3, batch=8, lr=3e-3), SMALL, "cpu"))
    errs, _ = example_errors(load_run(tmp_path / "run"))
    assert np.isfinite(errs.force_err).all() and np.isfinite(errs.ld_mean).all()
    assert np.abs(errs.force_err).max() < 1e-4                    # truth: at most 5 uN


def test_forces_at_the_sensor_limit_are_kept_and_beyond_it_flagged() -> None:
    raw = SimpleNamespace(calibration=SimpleNamespace(max_load=NANO17_MAX))
    at_limit = np.vstack([NANO17_MAX, -NANO17_MAX, np.full(6, 1e-12), np.zeros(6)])
    assert not beyond_rating(at_limit, raw.calibration).any()
    beyond = np.vstack([NANO17_MAX * (1 + 1e-6), -NANO17_MAX * (1 + 1e-6)])
    assert beyond_rating(beyond, raw.calibration).all()
    one_axis = np.zeros((1, 6))
    one_axis[0, 2] = -35.001
    assert beyond_rating(one_axis, raw.calibration).all()


def test_long_recordings_keep_exact_int64_nanoseconds() -> None:
    """A day at 500 Hz: every frame time is an exact multiple of 2 ms, where float32 seconds
    would be off by milliseconds. Float seconds since the start convert exactly after rounding;
    epoch seconds (1.7e9 s) hold only ~240 ns steps in float64, so their error stays below a
    quarter microsecond (1/4000 of a 1 kHz force sample), never growing with the length."""
    frames = 24 * 3600 * 500
    t = frame_times_ns(frames, 500.0, "day.tsv")
    assert t.dtype == np.int64 and t[-1] == (frames - 1) * 2_000_000
    assert (np.diff(t[-1000:]) == 2_000_000).all()
    index = np.arange(frames - 1000, frames)
    since_start = time_to_ns(index / 500.0, "log.csv")
    assert (since_start == index * 2_000_000).all()
    epoch = time_to_ns(index / 500.0 + 1.7e9, "log.csv")
    assert np.abs(epoch - (index * 2_000_000 + 1_700_000_000 * 10**9)).max() <= 250
    lossy = np.float32(index[-1] / 500.0)                         # what float32 would keep
    assert abs(float(lossy) - index[-1] / 500.0) > 1e-3           # why time is never float32


def _split(data: Path, out: Path, *extra: str):
    return CliRunner().invoke(cli, ["split", str(data), "--out", str(out), "--no-rrd", *extra])


def test_a_one_group_split_is_refused_with_the_reason(tmp_path) -> None:
    data, _ = _dent(tmp_path, manifest=False, places=1, repeats=1)
    res = _split(data, tmp_path / "s.json")
    assert res.exit_code == 2 and "Traceback" not in res.output
    assert f"{data}: ratio 12:3:5 does not fit 1 group(s)" in res.output
    assert not (tmp_path / "s.json").exists()


def test_an_empty_states_file_is_refused(tmp_path) -> None:
    data, _ = _dent(tmp_path, manifest=False, places=1, repeats=1)
    empty = tmp_path / "empty.h5"
    with h5py.File(data, "r") as src, h5py.File(empty, "w") as dst:
        for key, value in src.attrs.items():
            dst.attrs[key] = value
        for name in _datasets(src):
            dst.create_dataset(name, data=src[name][()][:0])
            dst[name].attrs.update(src[name].attrs)
    res = _split(empty, tmp_path / "s.json")
    assert res.exit_code == 2 and "Traceback" not in res.output
    assert f"{empty}: ratio 12:3:5 does not fit 0 group(s)" in res.output
    assert not (tmp_path / "s.json").exists()


def _datasets(f: h5py.File) -> list[str]:
    names: list[str] = []
    f.visititems(lambda name, obj: names.append(name) if isinstance(obj, h5py.Dataset) else None)
    return names


def test_a_training_set_smaller_than_a_batch_is_one_full_batch(tmp_path) -> None:
    """A batch larger than the training set is the whole set: the same weights as a batch of
    exactly its size."""
    data, splits = _dent(tmp_path)
    ids = role_examples(load_manifest(splits, data), 0, "train")
    size = sum(len(v) for v in ids.values())
    weights = []
    for batch in (10_000, size):
        best = run_train(TrainInputs(data, splits), tmp_path / f"b{batch}", TrainParams(
            TrainOptions(epochs=2, batch=batch, lr=3e-3), SMALL, "cpu")).best
        weights.append(load_checkpoint(best)["model"])
    assert 1 < size < 10_000
    for key in weights[0]:
        torch.testing.assert_close(weights[0][key], weights[1][key], rtol=1e-5, atol=1e-6)

"""Training, simulate and fit-msm at the extremes: each ends as a
correct result or one line naming the option, exit status 2, nothing written.

Training that cannot learn says so: no validation set, a loss that does not move, data in
which nothing moves. Numeric options are finite and bounded. The MSM's depth is held against
the phantom's thickness.
"""

from __future__ import annotations

import math
import pickle
import warnings
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch
from click.testing import CliRunner
from helpers.cgnn_data import write_dent_split, write_dent_states

from core.errors import BadInput
from core.protocol import THICKNESS_M
from core.recording import rrd_entities
from pipeline.cli import cli
from train.data import example_pairs, load_manifest, load_states, role_examples
from train.training.checkpoint import load_checkpoint
from train.training.fold_data import check_learnable
from train.training.train_params import TrainInputs, TrainOptions, TrainParams
from train.training.train_stage import run_train


def _run(*args: str):
    return CliRunner().invoke(cli, ["-q", *args])


def _one_line_refusal(result, names: str) -> str:
    """The refusal's line: exit 2, one line on stderr naming ``names``, no traceback."""
    assert result.exit_code == 2, result.output
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    assert names in lines[0], lines[0]
    assert ".tmp-" not in lines[0] and "millimetres" not in lines[0]    # no temporary file
    return lines[0]


@pytest.fixture(scope="module")
def dent(tmp_path_factory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("dent")
    data, splits = d / "states.h5", d / "splits.json"
    write_dent_states(data)
    write_dent_split(data, splits)
    return data, splits


def _train(dent, out: Path, *args: str, rrd: bool = False):
    return _run("train", "--data", str(dent[0]), "--splits", str(dent[1]), "--out", str(out),
                "--batch", "8", "--rrd" if rrd else "--no-rrd", *args)


# --- numeric options: finite and bounded, refused in one line naming the option -------------

@pytest.mark.parametrize("args,option", [
    (["--lr", "nan"], "--lr"), (["--lr", "inf"], "--lr"), (["--lr", "0"], "--lr"),
    (["--lr", "2"], "--lr"), (["--alpha", "inf"], "--alpha"), (["--alpha", "nan"], "--alpha"),
    (["--alpha", "0"], "--alpha"), (["--ema", "nan"], "--ema"),
    (["--point-fraction", "nan"], "--point-fraction"), (["--epochs", "0"], "--epochs"),
    (["--epochs", "2.5"], "--epochs"), (["--batch", "0"], "--batch"), (["--k", "1"], "--k"),
])
def test_train_refuses_extreme_options_in_one_line(dent, tmp_path, args, option):
    line = _one_line_refusal(_train(dent, tmp_path / "run", *args), option)
    assert "diverged" not in line
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("field", ["lr", "alpha", "ema", "point_fraction"])
def test_a_caller_s_nan_options_are_refused_before_training(dent, tmp_path, field):
    """The same guard for code calling the loop (benchmarks, eval's scarcity retraining): the
    options refuse it as they are made."""
    with pytest.raises(BadInput, match=f"{field} nan: not a finite number"):
        opts = TrainOptions(epochs=1, **{field: math.nan})
        run_train(TrainInputs(*dent), tmp_path / "run", TrainParams(opts, device="cpu"))
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("args,option", [
    (["--fmax", "nan"], "--fmax"), (["--fmax", "inf"], "--fmax"), (["--fmax", "0"], "--fmax"),
    (["--fmax", "1e4"], "--fmax"), (["--fmax", "100"], "--fmax"),
    (["--k-fixed", "nan"], "--k-fixed"), (["--k-between", "-inf"], "--k-between"),
    (["--tol", "nan"], "--tol"), (["--max-angle", "nan"], "--max-angle"),
    (["--thickness", "nan"], "--thickness"), (["--steps", "0"], "--steps"),
])
def test_simulate_refuses_extreme_options_in_one_line(tmp_path, args, option):
    out = tmp_path / "msm.h5"
    result = _run("simulate", "--out", str(out), "--locations", "2", "--directions", "1",
                  "--steps", "3", "--workers", "1", *args)
    _one_line_refusal(result, option)
    assert not out.exists() and not out.with_suffix(".rrd").exists()
    assert list(tmp_path.iterdir()) == []                 # no temporary file left either


def test_a_force_driving_the_msm_through_the_block_names_force_and_thickness(tmp_path):
    """100 N at the paper's constants: the loaded mass would go ~0.3-0.8 m deep."""
    line = _one_line_refusal(_run("simulate", "--out", str(tmp_path / "m.h5"), "--locations",
                                  "3", "--directions", "1", "--steps", "2", "--fmax", "100",
                                  "--workers", "1"), "--fmax 100 N")
    assert f"{THICKNESS_M * 1e3:g} mm thickness" in line and "stiffen the springs" in line


@pytest.mark.parametrize("args,option", [
    (["--start", "nan", "21"], "--start"), (["--start", "100", "inf"], "--start"),
    (["--contact-radius", "nan"], "--contact-radius"),
])
def test_fit_msm_refuses_non_finite_options(dent, tmp_path, args, option):
    _one_line_refusal(_run("fit-msm", str(dent[0]), "--out", str(tmp_path / "p.json"), *args),
                      option)
    assert not (tmp_path / "p.json").exists()


def test_states_deeper_than_the_phantom_are_counted(tmp_path):
    """The paper's 7.5 N at 100 and 21 N/m: edge masses go deeper than 32 mm. Every such
    state (its tip below -thickness in the file) is counted in the closing line."""
    out = tmp_path / "msm.h5"
    result = _run("simulate", "--out", str(out), "--locations", "6", "--directions", "1",
                  "--steps", "3", "--workers", "1", "--no-rrd", "--seed", "0")
    assert result.exit_code == 0, result.output
    with h5py.File(out) as f:
        depth = -f["states/tip"][()][:, 2].astype(float)
    deep = int((depth > THICKNESS_M).sum())
    assert deep > 0                                # seed 0 draws an edge mass: ~70 mm
    assert f"{deep} states deeper than the phantom's 32 mm thickness" in result.output
    assert f"deepest {depth.max() * 1e3:.1f} mm" in result.output
    thick = _run("simulate", "--out", str(tmp_path / "t.h5"), "--locations", "6",
                 "--directions", "1", "--steps", "3", "--workers", "1", "--no-rrd",
                 "--thickness", "0.09")
    assert thick.exit_code == 0 and "within the phantom's 90 mm" in thick.output


# --- training that cannot learn says so -----------------------------------------------------

def test_a_fold_without_validation_is_refused_unless_no_val(tmp_path):
    data, splits = tmp_path / "s.h5", tmp_path / "noval.json"
    write_dent_states(data)
    write_dent_split(data, splits, ratio=(3, 0, 1))
    line = _one_line_refusal(_train((data, splits), tmp_path / "run", "--epochs", "2"),
                             str(splits))
    assert "no validation" in line and "--no-val" in line
    assert not (tmp_path / "run" / "best.pt").exists()
    result = _train((data, splits), tmp_path / "run", "--epochs", "3", "--no-val")
    assert result.exit_code == 0, result.output
    assert "the last epoch: --no-val" in result.stdout
    best = load_checkpoint(tmp_path / "run" / "best.pt")
    last = load_checkpoint(tmp_path / "run" / "last.pt")
    assert best["epoch"] == last["epoch"] == 2
    for k, w in last["model"].items():
        assert torch.equal(best["model"][k], w)
    assert any("--no-val" in n for n in last["meta"]["notes"])


@pytest.mark.parametrize("epochs", ["1", "3"])
def test_a_loss_that_does_not_move_is_warned_of(dent, tmp_path, epochs):
    """--lr 1e-9 moves the dent's loss by ~1e-6 of itself (the default 1e-4: ~1e-1): a
    warning line on stderr, kept in the checkpoint and the recording, however short the run;
    a learning rate that learns (3e-3) raises none."""
    stuck = _train(dent, tmp_path / "stuck", "--epochs", epochs, "--lr", "1e-9", rrd=True)
    assert stuck.exit_code == 0, stuck.output
    warned = [line for line in stuck.stderr.splitlines() if line.startswith("warning:")]
    assert len(warned) == 1 and "did not move" in warned[0] and "--lr" in warned[0]
    assert "1 warning(s)" in stuck.stdout
    notes = load_checkpoint(tmp_path / "stuck" / "last.pt")["meta"]["notes"]
    assert any("did not move" in n for n in notes)
    assert rrd_entities(tmp_path / "stuck" / "train.rrd")["/notes/0"] == {"TextLog"}
    learns = _train(dent, tmp_path / "learns", "--epochs", epochs, "--lr", "3e-3")
    assert learns.exit_code == 0 and "warning" not in learns.output


def _still_copy(src: Path, dst: Path, force_changes: bool) -> None:
    """``dst``: the dent states with every state's points those of the first (nothing moves,
    up to 1e-10 m of noise), and the force zero or as it was."""
    dst.write_bytes(src.read_bytes())
    with h5py.File(dst, "r+") as f:
        pts = f["states/points"][()]
        noise = np.random.default_rng(0).normal(0, 1e-10, pts.shape)
        f["states/points"][...] = (pts[0][None] + noise).astype(np.float32)
        if not force_changes:
            f["states/force"][...] = 0


def test_data_with_nothing_to_learn_is_refused_before_training(dent, tmp_path):
    data, splits = tmp_path / "still.h5", tmp_path / "still.json"
    _still_copy(dent[0], data, force_changes=False)
    write_dent_split(data, splits)
    line = _one_line_refusal(_train((data, splits), tmp_path / "run", "--epochs", "1"),
                             str(data))
    assert "nothing to learn" in line
    assert not (tmp_path / "run" / "best.pt").exists()


def test_a_force_that_changes_is_something_to_learn(dent, tmp_path):
    """Points still, force changing (a stiff block): trained, not refused."""
    data, splits = tmp_path / "stiff.h5", tmp_path / "stiff.json"
    _still_copy(dent[0], data, force_changes=True)
    write_dent_split(data, splits)
    states = load_states(data)
    pairs = example_pairs(states, role_examples(load_manifest(splits, data), 0, "train"))
    check_learnable(states, pairs, data, 0)                 # no refusal
    with pytest.raises(BadInput, match="nothing to learn"):
        check_learnable(replace(states, force=states.force * 0), pairs, data, 0)


# --- a refused checkpoint: our one line, not torch's warning before it ----------------------

class _TrainCall:
    def __reduce__(self):
        return (print, ("a checkpoint that runs code",))


@pytest.mark.parametrize("how", ["pickle", "torch"])
def test_a_pickled_call_is_refused_without_torch_warnings(tmp_path, how):
    path = tmp_path / "evil.pt"
    if how == "pickle":
        path.write_bytes(pickle.dumps({"model": _TrainCall()}, protocol=4))
    else:
        torch.save({"model": _TrainCall()}, path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(BadInput) as e:
            load_checkpoint(path)
    assert [str(w.message) for w in caught] == []
    assert str(path) in e.value.line() and "\n" not in e.value.line()

"""The demo's worker processes train exactly what ``pipeline train`` trains in a process of its
own, in the order the steps' inputs allow, and a refusal in one of them ends the demo as the
command would: one line, exit status 2."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest
import torch
from helpers.cgnn_data import dent_fold

from pipeline.demo_plan import Step
from pipeline.demo_pool import Pool, StepResult

ROOT = Path(__file__).resolve().parents[2]


def _train(data: Path, splits: Path, run: Path, init: Path | None = None) -> Step:
    """A two-epoch run of the recipe on the dent states (fine-tuned from ``init``)."""
    more = ("--init", str(init)) if init else ()
    args = ("train", "--data", str(data), "--splits", str(splits), "--out", str(run),
            "--epochs", "2", "--recipe", "ours", "--no-rrd", "--seed", "3", *more)
    return Step(args, (data, splits, *((init,) if init else ())), (run / "best.pt",), (run,),
                parallel=True, batch="t")


def _own_process(step: Step) -> None:
    """``pipeline -q ARGS`` as the demo ran it before its workers: one thread."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    subprocess.run([sys.executable, "-m", "pipeline", "-q", *step.args], env=env, cwd=ROOT,
                   check=True, stdout=subprocess.DEVNULL)


def _weights(run: Path) -> dict[str, dict[str, torch.Tensor]]:
    state = torch.load(run / "best.pt", weights_only=False)
    return {k: state[k] for k in ("model", "trained")}


def test_workers_train_the_same_weights_as_a_process_of_their_own(tmp_path):
    data, splits = dent_fold(tmp_path)
    pre, tl = tmp_path / "w" / "pre", tmp_path / "w" / "tl"
    steps = [_train(data, splits, tl, pre / "best.pt"), _train(data, splits, pre)]
    order, results = [], []
    with Pool(2, 1) as pool:           # the fine-tuning listed first waits for its init
        pool.run(steps, lambda s, w: order.append(s.outputs[0].parent.name),
                 lambda s, r: results.append(r))
    assert order == ["pre", "tl"]
    assert all(isinstance(r, StepResult) and r.rc == 0 and r.seconds > 0 for r in results)
    own_pre, own_tl = tmp_path / "p" / "pre", tmp_path / "p" / "tl"
    _own_process(_train(data, splits, own_pre))
    _own_process(_train(data, splits, own_tl, pre / "best.pt"))    # the same init
    for mine, theirs in ((pre, own_pre), (tl, own_tl)):
        a, b = _weights(mine), _weights(theirs)
        for key in a:
            assert a[key].keys() == b[key].keys()
            assert all(torch.equal(a[key][n], b[key][n]) for n in a[key]), (mine, key)
    prov = torch.load(tl / "best.pt", weights_only=False)["provenance"]
    assert prov["command"].split()[1:3] == ["-q", "train"]     # as the command line was


def test_a_refusal_in_a_worker_is_one_line_and_exit_status_2(tmp_path, capsys):
    data, splits = dent_fold(tmp_path)
    bad = _train(data, splits, tmp_path / "bad", init=splits)       # not a checkpoint
    with Pool(2, 1) as pool, pytest.raises(SystemExit) as stop:
        pool.run([bad], lambda s, w: None, lambda s, r: None)
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and str(splits) in err[0], err


def test_a_worker_that_dies_fails_its_step(tmp_path, capsys):
    """A worker killed in the middle of a step ends the demo with status 1 and says so."""
    data, splits = dent_fold(tmp_path)
    with Pool(1, 1) as pool, pytest.raises(SystemExit) as stop:
        def kill_soon(step: Step, worker: int) -> None:
            threading.Timer(0.5, pool._workers[0].process.kill).start()

        pool.run([_train(data, splits, tmp_path / "r")], kill_soon, lambda s, r: None)
    assert stop.value.code == 1
    assert "died" in capsys.readouterr().err

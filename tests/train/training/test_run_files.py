"""When a run writes its files (:mod:`train.training.run_files`): every epoch with ``every``
0, as runs did before; otherwise every ``every`` seconds and at the end, the best epoch's
weights kept as they were while training goes on, the log's rows in order. Whole runs that
resume, stop early or keep the average are ``test_train_stage.py``'s."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import pytest
import torch
from torch import nn

from train.training import run_files
from train.training.run_files import LOG_FIELDS, RunFiles, RunWriter, snapshot


class CallRecorder:
    """A ``save`` that keeps what each write held (name, epoch, a weight's value) and leaves
    a file, as the runner's does."""

    def __init__(self) -> None:
        self.saved: list[tuple[str, int, float]] = []

    def __call__(self, path: Path, state: dict) -> None:
        self.saved.append((path.name, state["epoch"], float(state["model"]["weight"][0, 0])))
        path.write_bytes(b"x")


def _state(model: nn.Linear, epoch: int) -> dict:
    """A checkpoint's state as the loop makes it: the model's own tensors, not copies."""
    return {"model": model.state_dict(), "epoch": epoch}


def _row(epoch: int) -> dict:
    return {"epoch": epoch, "train_loss": 1.0 / (epoch + 1), "val_loss": 0.5,
            "val_ld_mm": 0.1, "val_force_abs_n": 0.2, "seconds": 1.0, "samples_per_s": 10.0,
            "extra": "not logged"}


def _logged(files: RunFiles) -> list[int]:
    with open(files.log, newline="") as f:
        rows = list(csv.DictReader(f))
    assert not rows or tuple(rows[0]) == LOG_FIELDS
    return [int(r["epoch"]) for r in rows]


def _epochs(writer: RunWriter, model: nn.Linear, epochs: range, best: set[int]) -> None:
    """Epochs that each change the weight to the epoch's number, then report."""
    for e in epochs:
        with torch.no_grad():
            model.weight.fill_(float(e))
        writer.epoch(_state(model, e), _row(e), best=e in best)


def test_every_epoch_writes_last_and_best_only_when_it_is_the_best(tmp_path: Path) -> None:
    """``every`` 0: epoch 0 (the best) best.pt and last.pt, the log's header and row; epoch 1
    (not better) last.pt alone, a row appended; a run started over at epoch 0 starts the log
    afresh."""
    files, save = RunFiles.in_folder(tmp_path), CallRecorder()
    writer = RunWriter(files, save, every=0)
    _epochs(writer, nn.Linear(2, 1), range(2), best={0})
    assert save.saved == [("best.pt", 0, 0.0), ("last.pt", 0, 0.0), ("last.pt", 1, 1.0)]
    assert _logged(files) == [0, 1]
    _epochs(RunWriter(files, save, every=0), nn.Linear(2, 1), range(1), best={0})
    assert _logged(files) == [0]


def test_between_writes_the_best_epoch_keeps_its_weights(tmp_path: Path) -> None:
    """Nothing is written before ``every`` seconds; the end's write holds the best epoch's
    weights in best.pt as they were then (the run's tensors changed since), the latest in
    last.pt, and every epoch's row; a second write with nothing new writes nothing."""
    files, save = RunFiles.in_folder(tmp_path), CallRecorder()
    writer = RunWriter(files, save, every=math.inf)
    _epochs(writer, nn.Linear(2, 1), range(5), best={0, 2})
    assert save.saved == [] and not files.log.exists()
    writer.write()
    assert save.saved == [("best.pt", 2, 2.0), ("last.pt", 4, 4.0)]
    assert _logged(files) == [0, 1, 2, 3, 4]
    writer.write()
    assert len(save.saved) == 2


def test_the_files_are_written_every_so_many_seconds(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """With ``every`` 10 s: an epoch that ends 10 s or more after the last write writes what
    waits (the rows since, the best if a new one waits, last.pt), and the clock starts again;
    the rows are appended in order."""
    now = [0.0]
    monkeypatch.setattr(run_files.time, "monotonic", lambda: now[0])
    files, save, model = RunFiles.in_folder(tmp_path), CallRecorder(), nn.Linear(2, 1)
    writer = RunWriter(files, save, every=10.0)
    for e, t in enumerate((3.0, 9.0, 10.5, 12.0, 21.0, 22.0)):
        now[0] = t
        _epochs(writer, model, range(e, e + 1), best={1, 3})
    assert save.saved == [("best.pt", 1, 1.0), ("last.pt", 2, 2.0),
                          ("best.pt", 3, 3.0), ("last.pt", 4, 4.0)]
    assert _logged(files) == [0, 1, 2, 3, 4]
    writer.write()
    assert save.saved[4:] == [("last.pt", 5, 5.0)] and _logged(files) == [0, 1, 2, 3, 4, 5]


def test_without_best_on_disk_the_first_epoch_is_kept_as_best(tmp_path: Path) -> None:
    """A run whose first epoch is not flagged best (a resumed run whose best.pt is gone)
    still leaves a best.pt: its first epoch's."""
    files, save = RunFiles.in_folder(tmp_path), CallRecorder()
    writer = RunWriter(files, save, every=math.inf)
    _epochs(writer, nn.Linear(2, 1), range(3, 5), best=set())
    writer.write()
    assert save.saved == [("best.pt", 3, 3.0), ("last.pt", 4, 4.0)]


def test_a_snapshot_is_not_changed_by_training_on() -> None:
    """An optimizer's state as a checkpoint holds it (dicts of tensors, lists of ids): the
    snapshot keeps its values when the original's tensors, dicts and lists change."""
    model = nn.Linear(2, 1)
    opt = torch.optim.Adam(model.parameters(), lr=0.1)
    model(torch.ones(1, 2)).sum().backward()
    opt.step()
    state = {"model": model.state_dict(), "optimizer": opt.state_dict(), "epoch": 3,
             "meta": {"notes": ["a"]}}
    kept = snapshot(state)
    before = {k: v.clone() for k, v in state["optimizer"]["state"][0].items()}
    opt.step()
    state["meta"]["notes"].append("b")
    state["optimizer"]["param_groups"][0]["params"].append(99)
    assert all(torch.equal(kept["optimizer"]["state"][0][k], v) for k, v in before.items())
    assert not torch.equal(kept["model"]["weight"], model.weight)
    assert kept["meta"]["notes"] == ["a"] and 99 not in kept["optimizer"]["param_groups"][0][
        "params"] and kept["epoch"] == 3

"""A training run's files and when they are written: ``best.pt``, ``last.pt`` and ``log.csv``,
every ``WRITE_EVERY`` seconds and at the run's end, not after every epoch.

A small run's epoch can take less time than writing its checkpoints (the figures:
docs/results.md, "Where a quicker demo could come from"). Between writes the log's rows wait
in memory, and so does the best epoch's state (a copy: training goes on); they are written
together, in this order: best.pt, last.pt, the log. A run killed between writes resumes from
the last one: it loses the epochs since (up to ``WRITE_EVERY`` seconds and the epoch under
way), and trains them again to the same weights (each epoch draws from a generator seeded by
the epoch, :mod:`train.training.loop`).
"""

from __future__ import annotations

import csv
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

WRITE_EVERY = 10.0     # s: how often a run writes its files (and at its end)
LOG_FIELDS = ("epoch", "train_loss", "val_loss", "val_ld_mm", "val_force_abs_n", "seconds",
              "samples_per_s")
Save = Callable[[Path, dict[str, Any]], None]    # writes a checkpoint (state) to a path


@dataclass(frozen=True)
class RunFiles:
    """Where a run's files go, named by its runner: the checkpoints ``best`` (the kept epoch)
    and ``last`` (the latest epoch written; a killed run resumes from it), and the per-epoch
    ``log`` (CSV, appended)."""

    best: Path
    last: Path
    log: Path

    @classmethod
    def in_folder(cls, out: Path) -> RunFiles:
        """A run folder's files: best.pt, last.pt, log.csv."""
        return cls(out / "best.pt", out / "last.pt", out / "log.csv")


def snapshot(value: Any) -> Any:
    """A copy of a checkpoint's state that training does not change: its tensors cloned, its
    dicts and lists copied, the rest (numbers, strings) shared. Several times cheaper than
    ``copy.deepcopy``, whose per-tensor bookkeeping cost more than writing the file."""
    if isinstance(value, torch.Tensor):
        return value.clone()
    if isinstance(value, dict):
        return {k: snapshot(v) for k, v in value.items()}
    if type(value) in (list, tuple):
        return type(value)(snapshot(v) for v in value)
    return value


class RunWriter:
    """Writes a run's files (``save`` the checkpoints, atomically) every ``every`` seconds
    (0: after each epoch) and when told to (:meth:`write`, at the run's end)."""

    def __init__(self, files: RunFiles, save: Save, every: float = WRITE_EVERY) -> None:
        self.files, self.save, self.every = files, save, every
        self._rows: list[dict[str, Any]] = []
        self._last: dict[str, Any] | None = None    # the latest epoch's state, unwritten
        self._best: dict[str, Any] | None = None    # the best epoch's, where not yet written
        self._written = time.monotonic()

    def epoch(self, state: dict[str, Any], row: dict[str, Any], best: bool) -> None:
        """After an epoch: its checkpoint ``state`` (its tensors the run's own, which the
        next epoch changes), its log ``row``, and whether it is the best so far (best.pt is
        also written where none is on disk yet). Everything waiting is written when
        ``every`` seconds have passed since the last write."""
        due = time.monotonic() - self._written >= self.every
        self._rows.append({k: row[k] for k in LOG_FIELDS})
        self._last = state
        if best or (self._best is None and not self.files.best.exists()):
            self._best = state if due else snapshot(state)
        if due:
            self.write()

    def write(self) -> None:
        """Write what waits: best.pt where a new best waits, last.pt, the log's rows (the log
        starts afresh with epoch 0). Call it only between epochs: last.pt is the state as the
        latest epoch left it."""
        if self._last is None:
            return
        if self._best is not None:
            self.save(self.files.best, self._best)
        self.save(self.files.last, self._last)
        log, first = self.files.log, self._rows[0]["epoch"]
        new = not log.exists() or first == 0
        with open(log, "w" if new else "a", newline="") as f:
            w = csv.DictWriter(f, fieldnames=LOG_FIELDS)
            if new:
                w.writeheader()
            w.writerows(self._rows)
        self._rows, self._last, self._best = [], None, None
        self._written = time.monotonic()

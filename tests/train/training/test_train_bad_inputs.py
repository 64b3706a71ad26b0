"""pipeline train against damaged copies of the states file, the folds and the checkpoint
(``--init``) it reads.

The harness, the damage and the clean inputs: ``tests/helpers/bad_input_checks.py``,
``tests/helpers/file_damage.py``, ``tests/helpers/bad_input_fixtures.py``.
"""

from __future__ import annotations

from pathlib import Path

import torch
from helpers.bad_input_checks import TINY_RUN, Outcome, Pair, cli, fuzz, restamped
from helpers.file_damage import checkpoint_mutations, folds_mutations, states_mutations

pytest_plugins = ["helpers.bad_input_fixtures"]


def _weights(run: Path) -> dict:
    return torch.load(run / "best.pt", weights_only=True)["model"]


def _train(data: Path, splits: Path, out: Path, *extra: object) -> Outcome:
    return cli("train", "--data", data, "--splits", splits, "--out", out, *TINY_RUN, *extra)


def test_train_reads_states(clean_dent, tmp_path) -> None:
    pair = Pair("train <- states", clean_dent / "states.h5", lambda c: c / "states.h5",
                lambda p, c: (_train(p, restamped(clean_dent / "splits.json", p, c), c / "run"),
                              c / "run"),
                _weights, lambda run: _weights(run))
    fuzz(pair, states_mutations(clean_dent / "states.h5"), tmp_path)


def test_train_reads_folds(clean_dent, tmp_path) -> None:
    pair = Pair("train <- folds", clean_dent / "splits.json", lambda c: c / "splits.json",
                lambda p, c: (_train(clean_dent / "states.h5", p, c / "run"), c / "run"),
                _weights, _weights)
    fuzz(pair, folds_mutations(clean_dent / "splits.json"), tmp_path)


def test_train_init_reads_checkpoint(clean_dent, tmp_path) -> None:
    pair = Pair("train --init <- checkpoint", clean_dent / "run" / "best.pt",
                lambda c: c / "init.pt",
                lambda p, c: (_train(clean_dent / "states.h5", clean_dent / "splits.json",
                                     c / "run", "--init", p), c / "run"),
                _weights, _weights)
    fuzz(pair, checkpoint_mutations(clean_dent / "run" / "best.pt"), tmp_path)

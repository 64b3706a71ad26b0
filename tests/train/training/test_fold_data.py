"""A fold's examples for a run (:mod:`train.training.fold_data`): the manifest's ids through
the states file's pairs, the states file's digest, and the folds that cannot teach refused.
Runs whose examples do not move are ``test_train_extremes.py``'s."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from helpers.cgnn_data import DENT_NAMES

from core.errors import BadInput
from train.training.fold_data import fold_examples
from train.training.train_params import TrainOptions


def _manifest_pairs(data: Path, splits: Path, fold: int, role: str) -> np.ndarray:
    """A role's (start, end) state pairs read straight from the files: single then multi."""
    doc = json.loads(splits.read_text())
    part = doc["folds"][fold][role]
    with h5py.File(data) as f:
        return np.concatenate([np.stack([f[f"{s}/start"][()][part[s]], f[f"{s}/end"][()][part[s]]],
                                        1) for s in ("single", "multi")])


@pytest.mark.parametrize("fold", [0, 1])
def test_a_fold_s_examples_are_the_manifest_s(dent: tuple[Path, Path], fold: int) -> None:
    """Training and validation pairs are the manifest's ids through the file's pairs; the
    digest is the states file's sha256."""
    data, splits = dent
    states, train, val, sha = fold_examples(data, splits, TrainOptions(fold=fold))
    np.testing.assert_array_equal(train.numpy(), _manifest_pairs(data, splits, fold, "train"))
    np.testing.assert_array_equal(val.numpy(), _manifest_pairs(data, splits, fold, "val"))
    assert sha == hashlib.sha256(data.read_bytes()).hexdigest()
    assert states.points.shape == (len(states.valid), len(DENT_NAMES), 3)


def test_no_val_leaves_the_validation_examples_out(dent: tuple[Path, Path]) -> None:
    """--no-val on a fold that has validation examples: none are used (best.pt is then the
    last epoch, not chosen on examples the run was told not to use)."""
    _, train, val, _ = fold_examples(*dent, TrainOptions(no_val=True))
    assert len(val) == 0 and val.shape == (0, 2)
    assert len(train) == len(_manifest_pairs(*dent, 0, "train"))


def _edited(dent: tuple[Path, Path], tmp_path: Path, role: str) -> Path:
    """The manifest with fold 0's ``role`` emptied (its groups too)."""
    doc = json.loads(dent[1].read_text())
    doc["folds"][0][role] = {"groups": [], "single": [], "multi": []}
    if role == "train":
        doc["folds"][0]["train_subsets"] = []
    path = tmp_path / f"no_{role}.json"
    path.write_text(json.dumps(doc))
    return path


def test_a_fold_without_training_examples_is_refused(dent: tuple[Path, Path],
                                                     tmp_path: Path) -> None:
    """Nothing to train on is refused naming the manifest, even with --no-val."""
    splits = _edited(dent, tmp_path, "train")
    with pytest.raises(BadInput) as e:
        fold_examples(dent[0], splits, TrainOptions(no_val=True))
    assert str(e.value) == f"{splits}: fold 0 has no training example"


def test_a_fold_without_validation_examples_is_refused_unless_no_val(
        dent: tuple[Path, Path], tmp_path: Path) -> None:
    """No validation examples: refused naming the manifest and --no-val; with --no-val trained."""
    splits = _edited(dent, tmp_path, "val")
    with pytest.raises(BadInput) as e:
        fold_examples(dent[0], splits, TrainOptions())
    assert e.value.path == str(splits) and "fold 0 has no validation example" in e.value.what
    assert "--no-val" in e.value.what and "\n" not in e.value.what
    _, train, val, _ = fold_examples(dent[0], splits, TrainOptions(no_val=True))
    assert len(train) > 0 and len(val) == 0

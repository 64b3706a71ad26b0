"""The scarcity benchmark's per-fold fit on the run's own presses
(benchmarks/bench_scarcity.py): the manifest it fits on holds exactly those presses."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from helpers.cgnn_data import dent_fold
from helpers.paths import ROOT

from data_schema.json_docs import training_sequences, validate_folds

sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_scarcity import own_presses  # noqa: E402


def test_the_own_fit_reads_the_runs_first_n_presses_and_nothing_else(tmp_path: Path) -> None:
    _, splits = dent_fold(tmp_path, folds=2)
    doc = json.loads(splits.read_text())
    for fold in range(2):
        subsets = doc["folds"][fold]["train_subsets"]
        for n in range(1, len(subsets) + 1):
            cut = tmp_path / f"cut_{fold}_{n}.json"
            cut.write_text(json.dumps(own_presses(splits, fold, n)))
            validate_folds(cut)                              # still a manifest the fit reads
            assert sorted(training_sequences(cut, fold, "fit-msm")) == sorted(subsets[n - 1])
            other = 1 - fold
            assert json.loads(cut.read_text())["folds"][other] == doc["folds"][other]
    assert json.loads(splits.read_text()) == doc                  # the input is not modified

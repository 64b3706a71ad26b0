"""The data-scarcity study (:mod:`train.evaluation.scarcity`) on the dent data: a fine-tuned
run's fold retrained on its first training group, from scratch and from its pre-trained model,
beside the three references fitted on the same group. Held against what the study promises:
the rows it makes, each retraining's own settings (its subset, its init, the run's other
options), and the reference that learns nothing, whose L_d is the mean displacement of the
test examples, read from the states file directly; the curve averages the folds per group.
(Every group count through ``pipeline eval --scarcity``: ``test_train_stage.py``.)"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from helpers.cgnn_data import TINY, dent_fold

from data_schema.metrics_doc import FORCE_LINEAR, NEAREST_PRESS, NOTHING_MOVES, ScarcityRow
from train.evaluation.scarcity import curve, scarcity_rows, write_csv
from train.training.checkpoint import load_checkpoint
from train.training.train_params import TrainInputs, TrainOptions, TrainParams
from train.training.train_stage import run_train

OPTS = TrainOptions(epochs=1, batch=8, rotate=True)


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> tuple[Path, list[ScarcityRow], Path]:
    """A run fine-tuned (one epoch) from another, and its study on its first group."""
    d = tmp_path_factory.mktemp("scarcity")
    data, splits = dent_fold(d)
    run_train(TrainInputs(data, splits), d / "pre", TrainParams(OPTS, TINY, "cpu"))
    run_train(TrainInputs(data, splits, d / "pre" / "best.pt"), d / "run",
              TrainParams(OPTS, TINY, "cpu"))
    rows = scarcity_rows(d / "run", d / "study", epochs=1, most=1)
    return d, rows, splits


def test_each_group_count_has_both_models_and_the_three_references(study) -> None:
    _, rows, _ = study
    names = ["no TL", "TL", NOTHING_MOVES, NEAREST_PRESS, FORCE_LINEAR]
    assert [(r.groups, r.predictor) for r in rows] == [(1, p) for p in names]
    assert all(r.fold == 0 for r in rows)
    for r in rows:
        row = r.to_json()                         # as metrics.json and the CSV keep it
        if r.predictor in ("TL", "no TL"):
            assert 0 <= row["points_90"] <= 1 and 0 <= row["force_90"] <= 1
            for what in ("points", "force"):      # one press: the range it falls in by chance
                assert 0 <= row[f"{what}_90_low"] <= row[f"{what}_90_high"] <= 1
        else:                                     # a reference keeps no intervals
            assert "points_90" not in row and r.shares is None


def test_each_retraining_is_the_run_on_its_subset_with_its_init_or_none(study) -> None:
    d, _, _ = study
    run_meta = load_checkpoint(d / "run" / "best.pt")["meta"]
    for n in (1,):
        for tag, init in (("tl", str((d / "pre" / "best.pt").resolve())), ("notl", None)):
            meta = load_checkpoint(d / "study" / f"fold0_n{n:02d}_{tag}" / "best.pt")["meta"]
            assert meta["init"] == init
            assert meta["options"] == {**run_meta["options"], "train_groups": n}
            assert meta["config"] == run_meta["config"]


def test_the_reference_that_learns_nothing_is_the_test_examples_displacement(study) -> None:
    """Its mean L_d (mm): over the fold's test examples, the mean distance each point moves,
    from the states file (and its max L_d, the largest)."""
    d, rows, splits = study
    test = json.loads(splits.read_text())["folds"][0]["test"]
    with h5py.File(d / "states.h5", "r") as f:
        points = f["states/points"][()].astype(float)
        pairs = np.concatenate([np.c_[f[f"{s}/start"][()], f[f"{s}/end"][()]][test[s]]
                                for s in ("single", "multi")])
    moved = np.linalg.norm(points[pairs[:, 1]] - points[pairs[:, 0]], axis=2)
    want = float(moved.mean(axis=1).mean()) * 1e3
    still = [r for r in rows if r.predictor == NOTHING_MOVES]
    assert [r.ld_mean_mm for r in still] == pytest.approx([want], rel=1e-5)
    assert still[0].ld_max_mm == pytest.approx(float(moved.max(axis=1).mean()) * 1e3,
                                               rel=1e-5)


def test_the_curve_averages_the_folds_per_group_and_skips_what_is_missing() -> None:
    rows = [ScarcityRow(fold=f, groups=g, predictor="TL", ld_mean_mm=v, ld_max_mm=None,
                        force_abs_n=0.1)
            for f, g, v in ((0, 1, 2.0), (1, 1, 4.0), (0, 2, 1.0), (1, 2, None))]
    assert curve(rows, "TL", lambda r: r.ld_mean_mm) == ([1, 2], [3.0, 1.0])
    assert curve(rows, "no TL", lambda r: r.ld_mean_mm) == ([], [])


HEADER = ("fold,groups,predictor,ld_mean_mm,ld_max_mm,force_abs_n,points_90,force_90,"
          "points_90_low,points_90_high,force_90_low,force_90_high")


def test_the_csv_has_the_study_s_fields(study, tmp_path) -> None:
    """The CSV's columns, as the study has always written them; a reference's row leaves
    its model's columns empty."""
    _, rows, _ = study
    write_csv(tmp_path / "s.csv", rows)
    lines = (tmp_path / "s.csv").read_text().splitlines()
    assert lines[0] == HEADER and len(lines) == len(rows) + 1
    reference = lines[1 + [r.predictor for r in rows].index(NOTHING_MOVES)].split(",")
    assert reference[:3] == ["0", "1", NOTHING_MOVES] and reference[6:] == [""] * 6

"""Coverage on test presses against counts known by construction, pooled over folds by adding,
and the recording's points coloured by how far inside or outside their radius they fall."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from helpers.interval_table import FAR, HALF, NEAR, known_table

from data_schema.intervals_doc import Intervals
from data_schema.metrics_doc import Gain, Metrics, PooledRow, RunRow, Scores, SetMetrics
from train.data import Batch
from train.evaluation.coverage import coverage, coverage_doc
from train.evaluation.coverage_table import coverage_table
from train.evaluation.eval_view import write_eval_recording
from train.model.si_units import BatchPrediction
from train.training.calibrate import Residuals


def _residuals() -> Residuals:
    """Four points 5 mm from the tip's path (radius NEAR = 1 mm), two of them inside; four
    50 mm from it (radius FAR = 0.1 mm), three inside; two examples, one force inside."""
    err = np.array([0.5, 0.9, 1.1, 3.0, 0.05, 0.2, 0.05, 0.05]) * 1e-3
    dist = np.r_[np.full(4, 0.005), np.full(4, 0.05)]
    feats = np.column_stack([dist, np.full(8, 1e-3), np.zeros(8)])
    return Residuals(err, feats, np.repeat([0, 1], 4), np.array([0.1, -0.3]),
                     np.array([[1e-3, 0.0], [1e-3, 0.0]]))


def _doc(*args, **kwargs) -> dict:
    """:func:`coverage_doc` as metrics.json keeps it."""
    return coverage_doc(*args, **kwargs).to_json()


def test_coverage_counts_points_inside_their_radius() -> None:
    doc = _doc(coverage(known_table(), _residuals()), ld_mean_mm=0.275)
    for level in doc["levels"]:
        assert level["points"] == 8 and level["coverage"] == pytest.approx(5 / 8)
        assert level["mean_radius_mm"] == pytest.approx((4 * NEAR + 4 * FAR) / 8 * 1e3)
        assert level["force_coverage"] == pytest.approx(0.5)
        assert level["force_half_width_n"] == pytest.approx(HALF)
    near, far = doc["by_distance"]
    assert (near["from_mm"], near["to_mm"], near["points"], near["coverage"]) == \
        (0.1, 10.0, 4, 0.5)
    assert (far["from_mm"], far["to_mm"], far["coverage"]) == (40.0, None, 0.75)
    assert near["mean_radius_mm"] == pytest.approx(NEAR * 1e3)
    assert doc["radius_to_ld"] == pytest.approx(0.55 / 0.275)
    assert "tip_point" not in doc                  # the data have no point on the path


def test_the_tips_own_point_is_reported_apart() -> None:
    """A point on the tip's path (a lab's tip marker, within 0.1 mm of it) is counted at
    every level but kept out of the distance bins, reported as ``tip_point``."""
    r = _residuals()
    r.point_error = np.r_[r.point_error, 2e-3, 0.5e-3]
    r.point_features = np.r_[r.point_features, [[0.0, 1e-3, 0.0], [5e-5, 1e-3, 0.0]]]
    r.point_example = np.r_[r.point_example, 0, 1]
    doc = _doc(coverage(known_table(), r), ld_mean_mm=0.275)
    assert doc["levels"][1]["points"] == 10 and doc["levels"][1]["coverage"] == 0.6
    assert [b["points"] for b in doc["by_distance"]] == [4, 4]
    tip = doc["tip_point"]
    assert (tip["from_mm"], tip["to_mm"], tip["points"], tip["coverage"]) == (0.0, 0.1, 2, 0.5)
    assert tip["mean_radius_mm"] == pytest.approx(NEAR * 1e3)


def test_folds_pool_by_adding() -> None:
    one = coverage(known_table(), _residuals())
    doc = _doc(one + one, ld_mean_mm=0.275)
    assert doc["levels"][1]["points"] == 16 and doc["levels"][1]["coverage"] == 5 / 8


def test_each_share_carries_its_band_into_the_document_and_the_table() -> None:
    """The range each share falls in by chance sits beside it, level by level; none where
    none was measured (a run whose presses cannot be re-drawn)."""
    bands = {"points": [[0.5, 0.7], [0.55, 0.75], [0.6, 0.8]],
             "force": [[0.3, 0.9], [0.35, 0.95], [0.4, 1.0]]}
    intervals = coverage_doc(coverage(known_table(), _residuals()), 0.275, bands)
    doc = intervals.to_json()
    assert [v["band"] for v in doc["levels"]] == bands["points"]
    assert [v["force_band"] for v in doc["levels"]] == bands["force"]
    table = coverage_table(Scores(runs=[], overall=[_pooled("Exp", intervals)]),
                           lambda r, o: "TL")
    assert "| TL | Exp | all | 62.5% (50-70 %) / " in table and "50.0% (35-95 %) / " in table
    plain = _doc(coverage(known_table(), _residuals()), 0.275)
    assert "band" not in plain["levels"][0] and "force_band" not in plain["levels"][0]


def test_the_table_names_runs_that_share_a_fold_by_their_folder() -> None:
    """Each lab fold's MSM set is fold 0 of its own manifest: its rows name the run."""
    doc = coverage_doc(coverage(known_table(), _residuals()), ld_mean_mm=0.275)

    def runs(names: list[str], folds: list[int]) -> list[RunRow]:
        return [RunRow(run=f"out/runs/{n}", fold=f, test_set="MSM", intervals=doc,
                       **_ROW) for n, f in zip(names, folds, strict=True)]

    overall = [_pooled("MSM", doc)]
    shared = coverage_table(Scores(overall=overall, runs=runs(["msm_fold1", "msm_fold0"],
                                                              [0, 0])), lambda r, o: "MSM")
    assert _fold_cells(shared) == ["all", "msm_fold0", "msm_fold1"]
    apart = coverage_table(Scores(overall=overall, runs=runs(["tl_b", "tl_a"], [1, 0])),
                           lambda r, o: "MSM")
    assert _fold_cells(apart) == ["all", "0", "1"]


_METRICS = Metrics(n=1, force_mse_n2=0.0, force_abs_n=0.0, force_abs_sd_n=0.0,
                   ld_mean_mm=0.275, ld_mean_sd_mm=0.0, ld_max_mm=0.5, ld_max_sd_mm=0.0)
_ROW = {"label": "MSM", "variant": {"model": "cGNN"}, "metrics": SetMetrics(all=_METRICS),
        "references": {}, "gain": Gain(ld_reference=None, ld_reference_mm=None, ld_gain=None,
                                       force_reference=None, force_reference_n=None,
                                       force_gain=None)}


def _pooled(test_set: str, intervals: Intervals) -> PooledRow:
    """A variant's row on ``test_set`` with ``intervals`` (the rest beside the point)."""
    return PooledRow(test_set=test_set, folds=1, fold_ids=[0], fold_ld_mean_sd_mm=0.0,
                     folds_not_beating_references=[], intervals=intervals, **_ROW)


def _fold_cells(table: str) -> list[str]:
    """The fold column of the coverage table's rows (the distance table after it left out)."""
    rows = table.split("By distance")[0].splitlines()
    return [line.split(" | ")[2] for line in rows if line.startswith("| MSM |")]


def _colours(rrd: Path, entity: str) -> list[np.ndarray]:
    """The colours of each temporal row of ``entity``."""
    from rerun.chunk import RrdReader

    rows = []
    for chunk in RrdReader(str(rrd)).store().stream():
        if chunk.entity_path == entity and not chunk.is_static:
            col = chunk.to_record_batch().column("Points3D:colors")
            rows += [np.asarray(col[i].as_py(), np.uint32) for i in range(len(col))]
    return rows


def test_recording_colours_points_by_error_over_radius(tmp_path: Path) -> None:
    """Three points: well inside (green), at the radius (yellow), three times it (red)."""
    pts = torch.tensor([[[0.0, 0, 0], [0.01, 0, 0], [0.02, 0, 0]]])
    b = Batch(pts, pts, torch.ones(1, 3, dtype=torch.bool), torch.zeros(1, 6),
              torch.zeros(1))
    p = BatchPrediction(pts, torch.zeros(1))
    write_eval_recording(tmp_path / "e.rrd", [(b, p)], "run", "table",
                         [np.array([[0.0, 1.0, 3.0]])])
    (rgba,) = _colours(tmp_path / "e.rrd", "/interval/points")
    rgb = [((c >> 24) & 255, (c >> 16) & 255, (c >> 8) & 255) for c in rgba]
    assert rgb == [(40, 170, 70), (240, 210, 40), (220, 30, 30)]
    assert _colours(tmp_path / "e.rrd", "/surface/predicted")       # beside the surfaces

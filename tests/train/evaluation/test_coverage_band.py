"""The band a calibrated table's coverage falls in by chance: counts known by construction, the
same draws in every evaluation, wider where a press's errors move together, and a check that
holds an honestly calibrated table and refuses a table too narrow or too wide."""

from __future__ import annotations

import numpy as np
import pytest

from train.evaluation.coverage import coverage
from train.evaluation.coverage_band import band, redrawn_counts
from train.intervals.levels import REPORTED
from train.intervals.table import IntervalTable
from train.training.calibrate import Residuals, joined


def _presses(rng: np.random.Generator, presses: int, spread: float, points: int = 40,
             examples: int = 12) -> tuple[Residuals, np.ndarray]:
    """Held-out residuals of ``presses`` presses, each press's errors scaled by
    exp(N(0, ``spread``)) (0: every press alike), ``examples`` examples of ``points`` points
    a press; and each example's press."""
    parts, press = [], []
    for p in range(presses):
        scale = np.exp(rng.normal(0, spread)) if spread else 1.0
        n = points * examples
        feats = np.column_stack([rng.uniform(0, 0.04, n), np.full(n, 3e-3), np.zeros(n)])
        parts.append(Residuals(np.abs(rng.normal(0, 1e-4 * scale, n)), feats,
                               np.repeat(np.arange(examples), points),
                               rng.normal(0, 0.1 * scale, examples),
                               np.column_stack([np.full(examples, 3e-3), np.zeros(examples)])))
        press += [p] * examples
    return joined(parts), np.asarray(press)


def test_each_draw_scores_the_presses_left() -> None:
    """Two presses, one calibrating: each draw counts the other press's points and examples."""
    held, press = _presses(np.random.default_rng(0), 2, 0.0, points=5, examples=7)
    counts = redrawn_counts(held, press, calibrating=1, fold=0, draws=6)
    assert counts.shape == (6, len(REPORTED), 4)
    assert (counts[..., 1] == 35).all() and (counts[..., 3] == 7).all()
    assert (counts[..., 0] <= 35).all() and (counts[..., 2] <= 7).all()


def test_the_draws_repeat_and_differ_by_fold() -> None:
    held, press = _presses(np.random.default_rng(1), 6, 0.5)
    first = redrawn_counts(held, press, 3, fold=0, draws=20)
    assert np.array_equal(first, redrawn_counts(held, press, 3, fold=0, draws=20))
    assert not np.array_equal(first, redrawn_counts(held, press, 3, fold=1, draws=20))


def test_no_band_where_no_press_would_be_left() -> None:
    held, press = _presses(np.random.default_rng(2), 3, 0.0)
    assert redrawn_counts(held, press, calibrating=3, fold=0) is None
    assert redrawn_counts(held, press, calibrating=0, fold=0) is None


def test_the_band_is_the_central_share_of_the_draws() -> None:
    """Counts whose shares are 0.00, 0.01, ..., 1.00: the central 90 % is 0.05-0.95."""
    shares = np.linspace(0, 1, 101)
    counts = np.zeros((101, len(REPORTED), 4))
    counts[..., 0], counts[..., 1] = shares[:, None] * 200, 200
    counts[..., 2], counts[..., 3] = (1 - shares[:, None]) * 50, 50
    b = band(counts, share=0.9)
    assert np.allclose(b["points"], [[0.05, 0.95]] * len(REPORTED))
    assert np.allclose(b["force"], [[0.05, 0.95]] * len(REPORTED))


def _width(b: dict) -> float:
    level = REPORTED.index(0.9)
    return b["points"][level][1] - b["points"][level][0]


def test_presses_that_err_together_widen_the_band() -> None:
    rng = np.random.default_rng(3)
    alike = band(redrawn_counts(*_presses(rng, 8, 0.0), 3, fold=0, draws=100))
    apart = band(redrawn_counts(*_presses(rng, 8, 0.8), 3, fold=0, draws=100))
    assert _width(apart) > 2 * _width(alike)


def _fold(rng: np.random.Generator, narrow: float) -> tuple[np.ndarray, np.ndarray]:
    """One fold of 8 held-out presses that err apart (each scaled by exp(N(0, 0.3))): a
    table calibrated on 3 of them (its scores times ``narrow``: 1 is honest) scored on the
    other 5, as (inside, total) per reported level for the points and the force; and the
    re-drawn counts."""
    held, press = _presses(rng, 8, 0.3)
    cal = press < 3
    c = held.subset(cal)
    table = IntervalTable.fit(c.point_error * narrow, c.point_features,
                              np.abs(c.force_error) * narrow, c.force_features, 3)
    got = coverage(table, held.subset(~cal))
    observed = np.stack([got.inside, got.points, got.force_inside, got.examples], 1)
    return observed, redrawn_counts(held, press, 3, fold=int(rng.integers(1000)), draws=100)


@pytest.mark.parametrize("narrow, inside", [(1.0, True), (0.5, False), (1.5, False)])
def test_the_band_holds_a_calibrated_table_and_refuses_a_wrong_one(narrow: float,
                                                                    inside: bool) -> None:
    """Pooled over five folds, the honest table's shares lie in their bands; a table half as
    wide (calibrated on errors that are too small, as training presses' would be) or 1.5x as
    wide falls outside at some level (measured over seeds 4-11: the honest table inside on
    all 8, these two outside on all 8)."""
    rng = np.random.default_rng(4)
    folds = [_fold(rng, narrow) for _ in range(5)]
    observed = sum(f[0] for f in folds)
    b = band(sum(f[1] for f in folds))
    shares = np.stack([observed[:, 0] / observed[:, 1], observed[:, 2] / observed[:, 3]])
    bands = np.stack([b["points"], b["force"]])
    held = (bands[..., 0] <= shares) & (shares <= bands[..., 1])
    assert held.all() == inside

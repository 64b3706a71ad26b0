"""The band a calibrated table's coverage falls in by chance: counts known by construction, the
same draws in every evaluation, a permutation test's size, wider where a press's errors move
together, and a check that holds an honestly calibrated table and refuses a table too narrow or
too wide."""

from __future__ import annotations

import numpy as np
import pytest

from train.evaluation.coverage import coverage
from train.evaluation.coverage_band import band, counts_of, redrawn_counts
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


def _binomial(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` coverage counts (n, L, 4) of one distribution: 400 points and 60 examples, each
    share near its level, the force's and the points' drawn together with a shared shift."""
    shift = rng.normal(0, 0.02, (n, 1))
    p = np.clip(np.asarray(REPORTED)[None] + shift, 0, 1)
    return np.stack([rng.binomial(400, p), np.full(p.shape, 400),
                     rng.binomial(60, p), np.full(p.shape, 60)], -1).astype(float)


def test_a_coverage_like_the_draws_passes_but_for_one_time_in_a_hundred() -> None:
    """The observed counts drawn as the re-draws are: inside every band in about 99 % of 400
    trials (the permutation test's size); one share pushed beyond the draws: outside."""
    rng = np.random.default_rng(5)
    inside = []
    for _ in range(400):
        rows = _binomial(rng, 100)
        b = band(rows[0], rows[1:])
        got = np.stack([rows[0, :, 0] / 400, rows[0, :, 2] / 60])
        edges = np.stack([b["points"], b["force"]])
        inside.append(((edges[..., 0] <= got) & (got <= edges[..., 1])).all())
    assert 0.97 <= np.mean(inside) <= 1.0
    rows = _binomial(rng, 100)
    odd = rows[0].copy()
    odd[1, 2] = 30                                 # the force at 90 %: half its examples
    b = band(odd, rows[1:])
    assert not b["force"][1][0] <= 0.5 <= b["force"][1][1]
    assert b["points"][1][0] <= odd[1, 0] / 400 <= b["points"][1][1]


def _width(b: dict) -> float:
    level = REPORTED.index(0.9)
    return b["points"][level][1] - b["points"][level][0]


def test_presses_that_err_together_widen_the_band() -> None:
    rng = np.random.default_rng(3)
    alike, apart = (redrawn_counts(*_presses(rng, 8, spread), 3, fold=0, draws=100)
                    for spread in (0.0, 0.8))
    alike, apart = band(alike[0], alike[1:]), band(apart[0], apart[1:])
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
    redrawn = redrawn_counts(held, press, 3, fold=int(rng.integers(1000)), draws=100)
    return counts_of(coverage(table, held.subset(~cal))), redrawn


@pytest.mark.parametrize("narrow, inside", [(1.0, True), (0.5, False), (2.0, False)])
def test_the_band_holds_a_calibrated_table_and_refuses_a_wrong_one(narrow: float,
                                                                    inside: bool) -> None:
    """Pooled over five folds, the honest table's shares lie in their bands; a table half as
    wide (calibrated on errors that are too small, as training presses' would be) or twice
    as wide falls outside at some level (measured: the honest table inside on 39 of seeds
    0-39; on seeds 0-11, half and twice as wide outside on 12 of 12, 0.7x on 10, 1.5x on 6)."""
    rng = np.random.default_rng(4)
    folds = [_fold(rng, narrow) for _ in range(5)]
    observed = sum(f[0] for f in folds)
    b = band(observed, sum(f[1] for f in folds))
    shares = np.stack([observed[:, 0] / observed[:, 1], observed[:, 2] / observed[:, 3]])
    bands = np.stack([b["points"], b["force"]])
    held = (bands[..., 0] <= shares) & (shares <= bands[..., 1])
    assert held.all() == inside

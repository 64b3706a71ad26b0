"""How far a calibrated interval's coverage may fall from its level by chance alone.

A fold's intervals are calibrated on a few validation presses and scored on a few test presses,
and a press's examples err together (a press's force errors move as one), so the coverage of a
perfectly calibrated table swings by several points from fold to fold: which presses a fold
drew decides it (docs/results.md measures it). The band is that swing, measured on the run's
own errors: where the intervals are calibrated, a fold's held-out presses (its validation and
test presses) are exchangeable, so each re-draw takes as many of them as calibrated the table,
refits the table on them (:class:`~train.intervals.table.IntervalTable`, as training did) and
counts how many of the other presses' points and examples fall inside. The counts add over
folds draw by draw (each fold redrawn on its own), so a variant's pooled band is the pooled
coverage of :data:`DRAWS` joint re-draws. A coverage outside its band (:data:`SHARE` of the
draws) is not explained by the presses drawn: the table is too narrow or too wide.
"""

from __future__ import annotations

import numpy as np

from train.evaluation.coverage import coverage
from train.intervals.levels import REPORTED
from train.intervals.table import IntervalTable
from train.training.calibrate import Residuals

DRAWS = 200          # re-draws of the calibration presses per fold
SHARE = 0.99         # the band: the central share of the re-draws' coverage
SEED = 0             # the re-draws are the same in every evaluation (drawn per fold)


def redrawn_counts(held: Residuals, press: np.ndarray, calibrating: int, fold: int,
                   draws: int = DRAWS) -> np.ndarray | None:
    """Per re-draw and reported level, (points inside, points, examples inside, examples)
    (draws, L, 4) of the presses left when ``calibrating`` of the held-out presses (``press``:
    each example's press in ``held``) calibrate a table; None where no press would be left."""
    presses = np.unique(press)
    if not 0 < calibrating < len(presses):
        return None
    rng = np.random.default_rng((SEED, fold))
    out = np.zeros((draws, len(REPORTED), 4))
    for d in range(draws):
        cal = np.isin(press, rng.choice(presses, calibrating, replace=False))
        table = IntervalTable.fit(*_scores(held.subset(cal)), calibrating)
        c = coverage(table, held.subset(~cal))
        out[d] = np.stack([c.inside, c.points, c.force_inside, c.examples], 1)
    return out


def _scores(r: Residuals) -> tuple[np.ndarray, ...]:
    """A calibration's inputs to :meth:`IntervalTable.fit` (the force's score is |dF error|)."""
    return r.point_error, r.point_features, np.abs(r.force_error), r.force_features


def band(counts: np.ndarray, share: float = SHARE) -> dict[str, list[list[float]]]:
    """The central ``share`` of the re-draws' coverage, per reported level: ``points`` and
    ``force`` each a [low, high] pair per level, from counts (draws, L, 4) summed over folds."""
    tails = 100 * np.array([(1 - share) / 2, (1 + share) / 2])
    points = np.percentile(counts[..., 0] / counts[..., 1], tails, axis=0).T
    force = np.percentile(counts[..., 2] / counts[..., 3], tails, axis=0).T
    return {"points": points.tolist(), "force": force.tolist()}

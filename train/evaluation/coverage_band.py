"""How far a calibrated interval's coverage may fall from its level by chance alone.

A fold's intervals are calibrated on a few validation presses and scored on a few test presses,
and a press's examples err together (a press's force errors move as one), so the coverage of a
perfectly calibrated table swings by several points from fold to fold: which presses a fold
drew decides it (docs/results.md measures it). The band is that swing, measured on the run's
own errors: where the intervals are calibrated, a fold's held-out presses (its validation and
test presses) are exchangeable, so each re-draw takes as many of them as calibrated the table,
refits the table on them (:class:`~train.intervals.table.IntervalTable`, as training did) and
counts how many of the other presses' points and examples fall inside. The counts add over
folds draw by draw (each fold redrawn on its own), so a variant's pooled band stands on the
pooled coverage of :data:`DRAWS` joint re-draws. The observed coverage is judged as one more
draw (:func:`band`, a permutation test): a share outside its band is not explained by the
presses drawn, the table is too narrow or too wide; a calibrated table is refused at most
1 - :data:`SHARE` of the time.
"""

from __future__ import annotations

import numpy as np

from train.evaluation.coverage import Coverage, coverage
from train.intervals.levels import REPORTED
from train.intervals.table import IntervalTable
from train.training.calibrate import Residuals

DRAWS = 200          # re-draws of the calibration presses per fold
SHARE = 0.99         # a calibrated table's shares all inside their bands this often
SPREAD = 0.16        # a share's spread on each side: its median to this quantile (1 sd if normal)
SEED = 0             # the re-draws are the same in every evaluation (seeded by the fold and
#                      its presses, so that two manifests' fold 0 draw apart)


def redrawn_counts(held: Residuals, press: np.ndarray, calibrating: int, fold: int,
                   draws: int = DRAWS) -> np.ndarray | None:
    """Per re-draw and reported level, (points inside, points, examples inside, examples)
    (draws, L, 4) of the presses left when ``calibrating`` of the held-out presses (``press``:
    each example's press in ``held``) calibrate a table; None where no press would be left."""
    presses = np.unique(press)
    if not 0 < calibrating < len(presses):
        return None
    rng = np.random.default_rng([SEED, fold, *(int(p) % 2**32 for p in presses)])
    out = np.zeros((draws, len(REPORTED), 4))
    for d in range(draws):
        cal = np.isin(press, rng.choice(presses, calibrating, replace=False))
        table = IntervalTable.fit(*_scores(held.subset(cal)), calibrating)
        out[d] = counts_of(coverage(table, held.subset(~cal)))
    return out


def _scores(r: Residuals) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A calibration's inputs to :meth:`IntervalTable.fit` (the force's score is |dF error|)."""
    return r.point_error, r.point_features, np.abs(r.force_error), r.force_features


def counts_of(c: Coverage) -> np.ndarray:
    """A coverage's (points inside, points, examples inside, examples) per level (L, 4)."""
    return np.stack([c.inside, c.points, c.force_inside, c.examples], 1)


def band(observed: np.ndarray, counts: np.ndarray, share: float = SHARE
         ) -> dict[str, list[list[float]]]:
    """Per reported level, the [low, high] range of the points' and the force's share against
    which the ``observed`` counts (L, 4) are judged, from the re-draws' (draws, L, 4), both
    summed over the same folds. A permutation test made readable: the observed coverage is one
    more draw; each draw's distance from the draws' median, share by share in units of their
    spread on its side (:data:`SPREAD`), is taken at its worst share; the band is where that
    worst distance stays within what all but 1 - ``share`` of the draws reach. So the observed
    shares lie inside every band exactly when the test passes, and a calibrated table fails it
    at most 1 - ``share`` of the time, whichever of its 2L shares strays."""
    rows = np.concatenate([observed[None], counts])
    shares = np.concatenate([rows[..., 0] / rows[..., 1], rows[..., 2] / rows[..., 3]], 1)
    low, mid, high = np.quantile(shares, [SPREAD, 0.5, 1 - SPREAD], axis=0)
    down, up = _positive(mid - low), _positive(high - mid)
    worst = np.maximum((mid - shares) / down, (shares - mid) / up).max(1)     # (n,)
    allowed = int(np.floor((1 - share) * len(rows) + 1e-9))   # draws that may lie beyond
    cut = np.sort(worst)[len(rows) - 1 - allowed]
    edge = 1e-12                                   # the cut's own row stays inside in floats
    pairs = np.clip(np.stack([mid - cut * down - edge, mid + cut * up + edge], 1), 0.0, 1.0)
    levels = len(REPORTED)
    return {"points": pairs[:levels].tolist(), "force": pairs[levels:].tolist()}


def _positive(spread: np.ndarray) -> np.ndarray:
    """A share's spread on one side, kept above zero (a share every draw gives alike)."""
    return np.maximum(spread, 1e-9)

"""Whether a run's intervals hold: their coverage on its fold's test presses.

At each reported level (:data:`train.intervals.levels.REPORTED`): the share of test points
whose error lies within their radius, the mean radius, and the same for the force (the share
of test examples whose |dF error| lies within the half-width, the mean half-width); and at
90 %, by the points' distance from the tip's path (:data:`NEAR_MM` bins), so that "beside the
tip" and "far from it" are seen apart, the tip's own point (a lab's tip marker, within
:data:`~train.model.normalise.TIP_POINT` of the path) apart from them. The sums
(:class:`Coverage`) add over folds, so a variant's pooled row counts every test point once. A
run whose checkpoint keeps no intervals (from before them, or trained without validation) has
none, said in one line.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from core.progress import warn
from data_schema.intervals_doc import DistanceBin, IntervalLevel, Intervals
from train.data import Batch
from train.intervals.levels import REPORTED, level_index
from train.intervals.table import IntervalTable
from train.model.normalise import TIP_POINT
from train.model.si_units import BatchPrediction
from train.training.calibrate import Residuals, batch_residuals

NEAR_MM = (10.0, 20.0, 40.0)     # the distance bins' edges of the near/far report, mm
TIP_MM = TIP_POINT * 1e3         # nearer the tip's path than this: the tip's own point, mm
SHOWN = 0.9                      # the level of the near/far report and of the recording


@dataclass
class Coverage:
    """Counts and sums over test points and examples (per reported level, and per
    distance bin at :data:`SHOWN`, the first the tip's own point): they add over folds."""

    points: np.ndarray         # (L,) test points (the same at every level)
    inside: np.ndarray         # (L,) of them within their radius
    radius: np.ndarray         # (L,) sum of radii, m (inf: a radius unbounded)
    examples: np.ndarray       # (L,) test examples
    force_inside: np.ndarray   # (L,) of them with |dF error| within the half-width
    half_width: np.ndarray     # (L,) sum of half-widths, N
    near_points: np.ndarray    # (D,) test points per distance bin
    near_inside: np.ndarray    # (D,)
    near_radius: np.ndarray    # (D,) sum of radii at SHOWN, m

    def __add__(self, other: Coverage) -> Coverage:
        return Coverage(*(getattr(self, f.name) + getattr(other, f.name)
                          for f in fields(self)))


def coverage(table: IntervalTable, r: Residuals) -> Coverage:
    """The coverage of ``table`` on residuals ``r`` (a fold's test examples)."""
    dist, depth, height = r.point_features.T
    fdepth, fheight = r.force_features.T
    rows = []
    for level in REPORTED:
        i = level_index(level)
        radius = table.radii(i, dist, depth, height)
        half = table.force.widths(i, fdepth, fheight)
        rows.append((len(radius), (r.point_error <= radius).sum(), radius.sum(),
                     len(half), (np.abs(r.force_error) <= half).sum(), half.sum()))
    radius = table.radii(level_index(SHOWN), dist, depth, height)
    near = np.searchsorted(np.asarray((TIP_MM, *NEAR_MM)) * 1e-3, dist, side="right")
    bins = len(NEAR_MM) + 2
    points, inside, radii, examples, force_inside, half_width = (
        np.asarray(col, dtype=np.float64) for col in zip(*rows, strict=True))
    return Coverage(points, inside, radii, examples, force_inside, half_width,
                    np.bincount(near, minlength=bins).astype(np.float64),
                    np.bincount(near, (r.point_error <= radius).astype(float), minlength=bins),
                    np.bincount(near, radius, minlength=bins))


def coverage_doc(c: Coverage, ld_mean_mm: float | None,
                 band: dict[str, list[list[float]]] | None = None) -> Intervals:
    """A coverage as a metrics row keeps it (:class:`~data_schema.intervals_doc.Intervals`):
    per level the points' and the force's share inside and mean width (with a ``band``,
    :func:`train.evaluation.coverage_band.band`, the range each share falls in by chance), by
    distance at :data:`SHOWN` (the surface's points; the tip's own point, where there is one,
    apart), and the mean radius at :data:`SHOWN` over the mean L_d (intervals that cover by
    being huge show there)."""
    levels = [IntervalLevel(level=q, points=int(c.points[k]),
                            coverage=float(c.inside[k] / c.points[k]),
                            mean_radius_mm=_mean(c.radius[k], c.points[k], 1e3),
                            examples=int(c.examples[k]),
                            force_coverage=float(c.force_inside[k] / c.examples[k]),
                            force_half_width_n=_mean(c.half_width[k], c.examples[k], 1.0),
                            band=band["points"][k] if band else None,
                            force_band=band["force"][k] if band else None)
              for k, q in enumerate(REPORTED)]
    lows, highs = (0.0, TIP_MM, *NEAR_MM), (TIP_MM, *NEAR_MM, None)   # each bin's edges, mm
    near = [DistanceBin(from_mm=lows[d], to_mm=highs[d], points=int(c.near_points[d]),
                        coverage=float(c.near_inside[d] / c.near_points[d]),
                        mean_radius_mm=_mean(c.near_radius[d], c.near_points[d], 1e3))
            for d in range(len(c.near_points)) if c.near_points[d] > 0]
    shown = levels[REPORTED.index(SHOWN)].mean_radius_mm
    ratio = None if shown is None or not ld_mean_mm else shown / ld_mean_mm
    tip = [b for b in near if b.from_mm == 0.0]
    return Intervals(levels=levels, by_distance=[b for b in near if b.from_mm > 0],
                     radius_to_ld=ratio, tip_point=tip[0] if tip else None)


def _mean(total: float, count: float, unit: float) -> float | None:
    """``total / count`` in ``unit``; None where a width is unbounded."""
    return float(total / count * unit) if np.isfinite(total) else None


def absent(run: str) -> None:
    """Say, in one line, that a run has no intervals to score."""
    warn(f"{run}: intervals absent (its best.pt is from before them, or was trained without "
         "validation presses): no coverage reported; retrain it to have them")


def error_ratios(table: IntervalTable, b: Batch, p: BatchPrediction, level: float = SHOWN
                 ) -> np.ndarray:
    """Each point's error over its radius at ``level`` (B, N): at most 1 inside, above 1
    outside (NaN where the point is not valid)."""
    r = batch_residuals(b, p)
    dist, depth, height = r.point_features.T
    ratio = np.full(b.mask.shape, np.nan)
    ratio[b.mask.cpu().numpy()] = r.point_error / table.radii(level_index(level), dist, depth,
                                                               height)
    return ratio

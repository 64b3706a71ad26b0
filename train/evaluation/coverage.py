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

from collections.abc import Callable
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from core.progress import warn
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
    return Coverage(*(np.asarray(col, dtype=np.float64) for col in zip(*rows, strict=True)),
                    np.bincount(near, minlength=bins).astype(np.float64),
                    np.bincount(near, (r.point_error <= radius).astype(float), minlength=bins),
                    np.bincount(near, radius, minlength=bins))


def coverage_doc(c: Coverage, ld_mean_mm: float | None,
                 band: dict[str, list[list[float]]] | None = None) -> dict:
    """The JSON of a coverage: per level the points' and the force's share inside and mean
    width (with a ``band``, :func:`train.evaluation.coverage_band.band`, the range each share
    falls in by chance: ``band`` and ``force_band``), by distance at :data:`SHOWN` (the
    surface's points; the tip's own point, where there is one, as ``tip_point``), and the mean
    radius at :data:`SHOWN` over the mean L_d (``radius_to_ld``: intervals that cover by being
    huge show there)."""
    levels = [{"level": q, "points": int(c.points[k]),
               "coverage": float(c.inside[k] / c.points[k]),
               "mean_radius_mm": _mean(c.radius[k], c.points[k], 1e3),
               "examples": int(c.examples[k]),
               "force_coverage": float(c.force_inside[k] / c.examples[k]),
               "force_half_width_n": _mean(c.half_width[k], c.examples[k], 1.0),
               **({"band": band["points"][k], "force_band": band["force"][k]} if band else {})}
              for k, q in enumerate(REPORTED)]
    edges = (0.0, TIP_MM, *NEAR_MM, None)
    near = [{"from_mm": edges[d], "to_mm": edges[d + 1], "points": int(c.near_points[d]),
             "coverage": float(c.near_inside[d] / c.near_points[d]),
             "mean_radius_mm": _mean(c.near_radius[d], c.near_points[d], 1e3)}
            for d in range(len(c.near_points)) if c.near_points[d] > 0]
    shown = levels[REPORTED.index(SHOWN)]["mean_radius_mm"]
    ratio = None if shown is None or not ld_mean_mm else shown / ld_mean_mm
    tip = [b for b in near if b["from_mm"] == 0.0]
    return {"levels": levels, "by_distance": [b for b in near if b["from_mm"] > 0],
            "radius_to_ld": ratio, **({"tip_point": tip[0]} if tip else {})}


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


def coverage_table(result: dict, name: Callable[[dict, list[dict]], str]) -> str:
    """Markdown: per variant (pooled over its folds, then each fold) the share of test points
    inside their radius and the mean radius at each level, the same for the force, the mean
    radius over mean L_d; and at :data:`SHOWN` by distance from the tip's path. ``name``:
    a row's shown name among the overall rows (empty when no row has intervals)."""
    rows = [r for r in result["overall"] if r.get("intervals")]
    if not rows:
        return ""
    head = ["Model/Train set", "Test set", "fold",
            *(f"points {q:.0%}" for q in REPORTED), *(f"force {q:.0%}" for q in REPORTED),
            f"radius {SHOWN:.0%} / L_d"]
    lines = ["", "Intervals on the test presses, calibrated on each fold's validation presses "
                 "(share inside / mean radius or half-width; in brackets the range a "
                 "calibrated table's share falls in by chance, its calibration presses "
                 "re-drawn among the fold's held-out presses)", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in rows:
        shown = name(row, result["overall"])
        runs = [r for r in result["runs"] if r["variant"] == row["variant"]
                and r["test_set"] == row["test_set"] and r.get("intervals")]
        lines.append(_coverage_row(shown, row["test_set"], "all", row["intervals"]))
        lines += [_coverage_row(shown, r["test_set"], fold, r["intervals"])
                  for fold, r in sorted(zip(_fold_names(runs), runs, strict=True),
                                        key=lambda named: (named[1]["fold"], named[0]))]
    return "\n".join(lines) + "\n" + _near_table(rows, result["overall"], name)


def _fold_names(runs: list[dict]) -> list[str]:
    """Each run's fold as a row names it: its fold number, or its folder's name where two
    runs share a number (each MSM set is fold 0 of its own manifest, one per lab fold)."""
    folds = [r["fold"] for r in runs]
    if len(set(folds)) == len(folds):
        return [str(f) for f in folds]
    return [Path(r["run"]).name for r in runs]


def _coverage_row(name: str, test_set: str, fold: str, doc: dict) -> str:
    points = [f"{v['coverage']:.1%}{_band(v.get('band'))} / "
              f"{_width(v['mean_radius_mm'], 'mm')}" for v in doc["levels"]]
    force = [f"{v['force_coverage']:.1%}{_band(v.get('force_band'))} / "
             f"{_width(v['force_half_width_n'], 'N')}" for v in doc["levels"]]
    ratio = "–" if doc["radius_to_ld"] is None else f"{doc['radius_to_ld']:.2f}"
    return "| " + " | ".join([name, test_set, fold, *points, *force, ratio]) + " |"


def _near_table(rows: list[dict], overall: list[dict],
                name: Callable[[dict, list[dict]], str]) -> str:
    """At :data:`SHOWN`, pooled: share inside / mean radius by distance from the tip's path,
    the tip's own point first."""
    edges = (TIP_MM, *NEAR_MM)
    head = ["Model/Train set", "Test set", "tip's own point",
            *(f"{a:g}–{b:g} mm" for a, b in zip(edges, NEAR_MM, strict=False)),
            f">= {NEAR_MM[-1]:g} mm"]
    lines = ["", f"By distance from the tip's path, at {SHOWN:.0%} (share inside / mean "
                 "radius; points)", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in rows:
        doc = row["intervals"]
        cells = {b["from_mm"]: _near_cell(b) for b in doc["by_distance"]}
        tip = _near_cell(doc["tip_point"]) if "tip_point" in doc else "–"
        lines.append("| " + " | ".join([name(row, overall), row["test_set"], tip,
                                        *(cells.get(e, "–") for e in edges)]) + " |")
    return "\n".join(lines) + "\n"


def _near_cell(b: dict) -> str:
    return f"{b['coverage']:.1%} / {_width(b['mean_radius_mm'], 'mm')}; {b['points']}"


def _band(pair: list[float] | None) -> str:
    """' (83-95 %)' for a share's band, nothing where there is none."""
    return "" if pair is None else f" ({pair[0] * 100:.0f}-{pair[1] * 100:.0f} %)"


def _width(value: float | None, unit: str) -> str:
    return "unbounded" if value is None else f"{value:.3g} {unit}"

"""The intervals' coverage as Markdown, below Table 2 in ``metrics.md``: per variant (pooled
over its folds, then each fold) the shares inside and the mean widths at every reported level,
each beside the range it falls in by chance; and at :data:`~train.evaluation.coverage.SHOWN`
by distance from the tip's path."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from data_schema.intervals_doc import DistanceBin, Intervals
from data_schema.metrics_doc import PooledRow, Row, RunRow, Scores
from train.evaluation.coverage import NEAR_MM, SHOWN, TIP_MM
from train.intervals.levels import REPORTED

Name = Callable[[Row, list[PooledRow]], str]     # a row's shown name among the overall rows


def coverage_table(scores: Scores, name: Name) -> str:
    """Markdown: per variant (pooled over its folds, then each fold) the share of test points
    inside their radius and the mean radius at each level, the same for the force, the mean
    radius over mean L_d; and at :data:`SHOWN` by distance from the tip's path. ``name``:
    a row's shown name among the overall rows (empty when no row has intervals)."""
    rows = [(r, r.intervals) for r in scores.overall if r.intervals is not None]
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
    for row, pooled in rows:
        shown = name(row, scores.overall)
        runs = [(r, r.intervals) for r in scores.runs if r.variant == row.variant
                and r.test_set == row.test_set and r.intervals is not None]
        lines.append(_coverage_row(shown, row.test_set, "all", pooled))
        lines += [_coverage_row(shown, r.test_set, fold, doc)
                  for fold, (r, doc) in sorted(zip(_fold_names([r for r, _ in runs]), runs,
                                                   strict=True),
                                               key=lambda named: (named[1][0].fold, named[0]))]
    return "\n".join(lines) + "\n" + _near_table(rows, scores.overall, name)


def _fold_names(runs: list[RunRow]) -> list[str]:
    """Each run's fold as a row names it: its fold number, or its folder's name where two
    runs share a number (each MSM set is fold 0 of its own manifest, one per lab fold)."""
    folds = [r.fold for r in runs]
    if len(set(folds)) == len(folds):
        return [str(f) for f in folds]
    return [Path(r.run).name for r in runs]


def _coverage_row(name: str, test_set: str, fold: str, doc: Intervals) -> str:
    points = [f"{v.coverage:.1%}{_band(v.band)} / {_width(v.mean_radius_mm, 'mm')}"
              for v in doc.levels]
    force = [f"{v.force_coverage:.1%}{_band(v.force_band)} / "
             f"{_width(v.force_half_width_n, 'N')}" for v in doc.levels]
    ratio = "–" if doc.radius_to_ld is None else f"{doc.radius_to_ld:.2f}"
    return "| " + " | ".join([name, test_set, fold, *points, *force, ratio]) + " |"


def _near_table(rows: list[tuple[PooledRow, Intervals]], overall: list[PooledRow],
                name: Name) -> str:
    """At :data:`SHOWN`, pooled: share inside / mean radius by distance from the tip's path,
    the tip's own point first."""
    edges = (TIP_MM, *NEAR_MM)
    head = ["Model/Train set", "Test set", "tip's own point",
            *(f"{a:g}–{b:g} mm" for a, b in zip(edges, NEAR_MM, strict=False)),
            f">= {NEAR_MM[-1]:g} mm"]
    lines = ["", f"By distance from the tip's path, at {SHOWN:.0%} (share inside / mean "
                 "radius; points)", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row, doc in rows:
        cells = {b.from_mm: _near_cell(b) for b in doc.by_distance}
        tip = "–" if doc.tip_point is None else _near_cell(doc.tip_point)
        lines.append("| " + " | ".join([name(row, overall), row.test_set, tip,
                                        *(cells.get(e, "–") for e in edges)]) + " |")
    return "\n".join(lines) + "\n"


def _near_cell(b: DistanceBin) -> str:
    return f"{b.coverage:.1%} / {_width(b.mean_radius_mm, 'mm')}; {b.points}"


def _band(pair: list[float] | None) -> str:
    """' (83-95 %)' for a share's band, nothing where there is none."""
    return "" if pair is None else f" ({pair[0] * 100:.0f}-{pair[1] * 100:.0f} %)"


def _width(value: float | None, unit: str) -> str:
    return "unbounded" if value is None else f"{value:.3g} {unit}"

"""Scoring trained runs on their folds' test examples: the paper's Table 2, per run and pooled.

Per run and set (single, multi, both): force MSE, force absolute error mean +- sd, mean L_d
mean +- sd and max L_d mean +- sd over examples (mm), from each example's errors
(:mod:`train.evaluation.run_errors`). Runs of one variant (all its fields,
:class:`train.training.variant.Variant`, not its label) are pooled over their folds, and the
spread of the per-fold means is given beside. Every run and variant is scored beside the
no-learning references (:mod:`train.evaluation.references`) on the same test examples, with its
gain over the best of them: a model that does not beat them has learned nothing worth shipping.
With a lump, the same over it and away from it (:mod:`train.evaluation.lump`). The scores are
the rows of the metrics document (:mod:`data_schema.metrics_doc`); the tables of them are
:mod:`train.evaluation.metrics_table`'s.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from data_schema.intervals_doc import Calibration, Intervals
from data_schema.metrics_doc import (
    Gain,
    LumpPart,
    LumpRow,
    Metrics,
    PooledRow,
    RunRow,
    Scores,
    SetMetrics,
    beats,
)
from data_schema.places import place_ids
from train.data import SETS, example_pairs
from train.evaluation.coverage import Coverage, coverage_doc
from train.evaluation.coverage_band import band, counts_of
from train.evaluation.lump import Lump, press_xy
from train.evaluation.references import DISPLACEMENT, FORCE, NAMES, best_reference
from train.evaluation.run_coverage import coverage_and_band, fold_coverage
from train.evaluation.run_errors import (
    ExampleErrors,
    LoadedRun,
    example_errors,
    load_run,
    pool,
    reference_errors,
    subset,
)
from train.intervals.table import IntervalTable
from train.training.variant import Variant, recorded_variant, source_name


def metrics(e: ExampleErrors) -> SetMetrics:
    """Table 2 metrics for single, multi (each where there is one) and both (mm, N, N^2);
    L_d is None for a predictor that moves no point (the linear force reference)."""
    single, multi = (_metrics(e, e.set == name) for name in SETS)
    everything = _metrics(e, np.ones(len(e.set), bool))
    if everything is None:
        raise ValueError("no example to score")
    return SetMetrics(single=single, multi=multi, all=everything)


def _metrics(e: ExampleErrors, keep: np.ndarray) -> Metrics | None:
    """The metrics of the examples of ``keep`` (None where it keeps none)."""
    if not keep.any():
        return None
    fe = e.force_err[keep]
    mean, top = (_mm(values[keep]) for values in (e.ld_mean, e.ld_max))
    return Metrics(n=int(keep.sum()), force_mse_n2=float(np.mean(fe**2)),
                   force_abs_n=float(np.mean(np.abs(fe))),
                   force_abs_sd_n=float(np.std(np.abs(fe))),
                   ld_mean_mm=mean[0], ld_mean_sd_mm=mean[1], ld_max_mm=top[0],
                   ld_max_sd_mm=top[1])


def _mm(values: np.ndarray) -> tuple[float | None, float | None]:
    """Mean and sd (mm) of distances (m); None where any is not finite."""
    if not np.isfinite(values).all():
        return None, None
    return float(np.mean(values) * 1e3), float(np.std(values) * 1e3)


def gains(model: Metrics, refs: dict[str, Metrics]) -> Gain:
    """A model's mean L_d and force error against the best reference of each: the
    reference's name and value, and the model's relative gain (positive: the model is better;
    0.3 = 30 % lower error; None where either value is missing, as for a model whose
    predictions are not finite)."""
    ld_name, ld_ref = best_reference(refs, lambda m: m.ld_mean_mm, DISPLACEMENT)
    force_name, force_ref = best_reference(refs, lambda m: m.force_abs_n, FORCE)
    return Gain(ld_reference=ld_name, ld_reference_mm=ld_ref,
                ld_gain=_gain(model.ld_mean_mm, ld_ref), force_reference=force_name,
                force_reference_n=force_ref, force_gain=_gain(model.force_abs_n, force_ref))


def _gain(value: float | None, ref: float | None) -> float | None:
    return None if value is None or ref is None else (1 - value / ref if ref else 0.0)


@dataclass
class _LumpSplit:
    """A run's test examples over the lump (``over``, a mask) and away, and the intervals'
    coverage of each part (None where the run keeps none or the part has no example)."""

    over: np.ndarray
    covers: tuple[Coverage | None, Coverage | None]

    @property
    def masks(self) -> tuple[np.ndarray, np.ndarray]:
        return self.over, ~self.over


@dataclass
class _Scored:
    """One run's row and what pooling its variant's runs needs of it."""

    row: RunRow
    errors: ExampleErrors
    references: dict[str, ExampleErrors]
    cover: Coverage | None
    redrawn: np.ndarray | None
    split: _LumpSplit | None


def evaluate_runs(run_dirs: list[Path], device: str = "cpu", lump: Lump | None = None
                  ) -> Scores:
    """Metrics per run and per variant (pooled over its folds, with the spread over folds),
    each beside the no-learning references on the same test examples, and the gain over the
    best of them; with a ``lump``, the same over it and away from it. Runs are pooled only
    where their whole :class:`Variant` and test set are the same (two variants may share a
    label)."""
    groups: dict[tuple[Variant, str], list[_Scored]] = {}
    runs = []
    for run_dir in run_dirs:
        run = load_run(run_dir, device)
        variant, test_set = recorded_variant(run.meta), source_name(run.meta["data"]["file"])
        scored = _score_run(run, run_dir, variant, test_set, lump)
        runs.append(scored.row)
        groups.setdefault((variant, test_set), []).append(scored)
    return Scores(runs=runs, overall=[_pooled(v, test_set, items, lump)
                                      for (v, test_set), items in groups.items()])


def _score_run(run: LoadedRun, run_dir: Path, variant: Variant, test_set: str,
               lump: Lump | None) -> _Scored:
    """One run's row beside the references, and (with a ``lump``) over it and away."""
    errs = example_errors(run)[0]
    refs = reference_errors(run)
    m = metrics(errs)
    ref_m = {n: metrics(e).all for n, e in refs.items()}
    cover, redrawn = coverage_and_band(run, run_dir)
    split = None
    if lump is not None:
        over = lump.over(press_xy(run.states, example_pairs(run.states, run.test)))
        split = _LumpSplit(over, (fold_coverage(run, run_dir, over, quiet=True),
                                  fold_coverage(run, run_dir, ~over, quiet=True)))
    row = RunRow(run=str(run_dir), label=variant.label, variant=variant.to_dict(),
                 fold=run.meta["options"]["fold"], test_set=test_set, metrics=m,
                 references=ref_m, gain=gains(m.all, ref_m),
                 intervals=_intervals(cover, m, run.intervals, redrawn),
                 lump=None if lump is None or split is None
                 else _lump_row(lump, errs, refs, split.masks, split.covers))
    return _Scored(row, errs, refs, cover, redrawn, split)


def _lump_row(lump: Lump, errs: ExampleErrors, refs: dict[str, ExampleErrors],
              masks: tuple[np.ndarray, np.ndarray],
              covers: tuple[Coverage | None, Coverage | None]) -> LumpRow:
    """A row's lump: the lump, and per part (over, away) the model's "all" metrics, the
    references' on the same examples, the gain and the intervals' coverage; a part with no
    test example is None."""
    over, away = (_lump_part(errs, refs, keep, cover)
                  for keep, cover in zip(masks, covers, strict=True))
    return lump.row(over, away)


def _lump_part(errs: ExampleErrors, refs: dict[str, ExampleErrors], keep: np.ndarray,
               cover: Coverage | None) -> LumpPart | None:
    """One part of a lump's row: the examples of ``keep`` (None where it keeps none)."""
    if not keep.any():
        return None
    m = metrics(subset(errs, keep)).all
    ref_m = {n: metrics(subset(e, keep)).all for n, e in refs.items()}
    return LumpPart(metrics=m, references=ref_m, gain=gains(m, ref_m),
                    intervals=None if cover is None else coverage_doc(cover, m.ld_mean_mm))


def _intervals(cover: Coverage | None, m: SetMetrics, table: IntervalTable | None = None,
               redrawn: np.ndarray | None = None) -> Intervals | None:
    """A row's intervals: their coverage, with the band it is judged against where the
    re-drawn calibrations' ``redrawn`` counts are given (and, for a run, the calibration
    they stand on); None where they are absent."""
    if cover is None:
        return None
    doc = coverage_doc(cover, m.all.ld_mean_mm,
                       None if redrawn is None else band(counts_of(cover), redrawn))
    if table is not None:
        doc = replace(doc, calibration=Calibration(presses=table.presses,
                                                   examples=table.examples))
    return doc


def _pooled(variant: Variant, test_set: str, items: list[_Scored], lump: Lump | None = None
            ) -> PooledRow:
    """The overall row of one variant on one test set: its runs pooled over their folds."""
    pooled = metrics(pool([s.errors for s in items]))
    refs = {n: pool([s.references[n] for s in items]) for n in NAMES}
    ref_m = {n: metrics(e).all for n, e in refs.items()}
    fold_ld = [v for v in (s.row.metrics.all.ld_mean_mm for s in items) if v is not None]
    return PooledRow(
        label=variant.label, variant=variant.to_dict(), test_set=test_set, folds=len(items),
        fold_ids=[s.row.fold for s in items], metrics=pooled,
        fold_ld_mean_sd_mm=float(np.std(fold_ld or [0.0])), references=ref_m,
        gain=gains(pooled.all, ref_m),
        folds_not_beating_references=[s.row.fold for s in items
                                      if not beats(s.row.gain.ld_gain)],
        intervals=_intervals(_sum_coverage([s.cover for s in items]), pooled,
                             redrawn=_summed([s.redrawn for s in items])),
        lump=None if lump is None else _pooled_lump(lump, items, refs))


def _pooled_lump(lump: Lump, items: list[_Scored], refs: dict[str, ExampleErrors]
                 ) -> LumpRow:
    """A variant's lump row: its runs' parts pooled (each part's coverage over the folds
    with test examples in it)."""
    splits = [s.split for s in items if s.split is not None]
    masks = tuple(np.concatenate([s.masks[k] for s in splits]) for k in (0, 1))
    covers = tuple(_sum_coverage([s.covers[k] for s in splits if s.masks[k].any()])
                   for k in (0, 1))
    return _lump_row(lump, pool([s.errors for s in items]), refs, (masks[0], masks[1]),
                     (covers[0], covers[1]))


def _sum_coverage(covers: list[Coverage | None]) -> Coverage | None:
    """Coverages pooled; None where any is missing (or there is none)."""
    present = [c for c in covers if c is not None]
    if not covers or len(present) < len(covers):
        return None
    total = present[0]
    for c in present[1:]:
        total = total + c
    return total


def _summed(redrawn: list[np.ndarray | None]) -> np.ndarray | None:
    """Folds' re-drawn counts added draw by draw; None where any is missing."""
    present = [r for r in redrawn if r is not None]
    if not redrawn or len(present) < len(redrawn):
        return None
    return np.sum(present, axis=0)


def footprint_errors(run: LoadedRun, lump: Lump | None = None
                     ) -> tuple[np.ndarray, np.ndarray, Lump | None]:
    """A run's test presses on the footprint: each place's (x, y) (K, 2) m (the mean of its
    examples' tips at their start) and mean L_d (K,) m over its examples (a place: the
    states' location id, :mod:`data_schema.places`), and the lump if any: for the
    recording."""
    errs = example_errors(run)[0]
    pairs = example_pairs(run.states, run.test)
    xy = press_xy(run.states, pairs)
    location = None if run.states.location is None else \
        run.states.location[pairs[:, 0].cpu().numpy()]
    which = place_ids(location, len(xy))
    count = np.bincount(which)
    centre = np.stack([np.bincount(which, xy[:, k]) / count for k in (0, 1)], 1)
    return centre, np.bincount(which, errs.ld_mean) / count, lump

"""The demo's summary: every result beside its target, so a miss is impossible to overlook.

Targets (the references are the predictors that learn nothing, scored on the same test
examples, :mod:`train.evaluation.references`):

- sync against the twin's truth (:data:`sync.sync_accuracy.TARGETS`);
- with the per-fold pre-training, the MSM fitted per fold at most half as far from that
  fold's training presses as a still surface;
- the MSM-trained model (the generic one, or each fold's) on its own test set: mean L_d at most
  half of "nothing moves", force error below the linear reference;
- fine-tuned with transfer learning (TL) and from scratch: mean L_d at least 30 % below the
  best reference in every fold; force error at most half the linear reference's;
- with a lump (``--inclusion``): the same 30 % in every fold over the lump (the test presses
  within its radius plus the reach, :data:`train.evaluation.lump.LUMP_REACH_M`, beside the
  references on those presses) and away from it;
- TL: pooled mean L_d at least 10 % below scratch trained as many epochs (the paper reports
  23 %, against a scratch model of its own), better in all folds but one; in the data-scarcity
  study, at least 30 % below scratch at every number of training presses shown;
- intervals (calibrated on each fold's validation presses), TL and scratch, on the test
  presses pooled over the folds: the share of points inside their 80, 90 and 95 % radii and
  of changes of force inside their intervals each inside its band, the range a calibrated
  table's share falls in by chance when the calibration presses are re-drawn among the
  fold's held-out presses (:mod:`train.evaluation.coverage_band`; a fold's 3 calibration and
  5 test presses swing it by several points, so "within 3 points in every fold" failed
  calibrated tables); each run's mean 90 % radius at most 3x its mean L_d, and points beside
  the tip's path given larger radii than points far from it; the 90 % shares of the scarcity
  study's models with the fewest training presses each inside its fold's band;
- the quick demo within 85 times the host's figure (:mod:`core.host_speed`; 5 minutes where the
  figure was not measured).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from data_schema.intervals_doc import DistanceBin, IntervalLevel
from data_schema.metrics_doc import (
    FORCE_LINEAR,
    LUMP_PARTS,
    NEAREST_PRESS,
    NOTHING_MOVES,
    LumpPart,
    Metrics,
    Row,
    RunRow,
    ScarcityRow,
    Scores,
    validate_metrics,
)
from pipeline.demo_plan import msm_dir
from train.training.variant import SOURCE_NAMES, Variant

FOLD_GAIN = 0.30        # every fold: mean L_d this far below the best reference
TL_CUT = 0.10           # pooled: TL this far below scratch at equal epochs
SCARCITY_CUT = 0.30     # scarcity study: TL this far below scratch at each size
FORCE_VS_LINEAR = 0.5   # force error at most this fraction of the linear reference's
FORCE_OVER_AWAY = 1.3   # pooled: the force's error over a lump at most this times away (58)
SOLID_OVER_LUMP = 0.15  # TL from the solid: pooled L_d over a lump this far below the shipped
#                         model's TL on the same examples (issue 58)
MSM_VS_STILL = 0.5      # MSM model (and the fit) at most this fraction of a still surface's
RADIUS_VS_LD = 3.0      # the mean 90 % radius at most this times the mean L_d
QUICK_HOST_UNITS = 85   # the quick demo's time, in host figures
QUICK_MINUTES = 5.0     # ... where the host's figure was not measured


def summary(out: Path, seconds: float, quick: bool, host_s: float | None = None) -> list[str]:
    """Print every result against its target; return the names of the targets missed.
    ``host_s``: the host's figure (s), the unit of the demo's time, when measured."""
    checks: list[tuple[str, bool, str]] = []
    checks += _sync(out)
    checks += _fit(out)
    click.echo("\n" + (out / "metrics.md").read_text())
    scores = Scores.from_json(validate_metrics(out / "metrics.json"))
    checks += _msm_model(scores)
    checks += _fine_tuned(scores)
    checks += _over_lump(scores)
    checks += _solid_over_lump(scores)
    checks += _force_over_lump(scores)
    checks += _intervals(scores)
    checks += _scarcity(out)
    if quick:
        checks.append(_quick_time(seconds, host_s))
    click.echo("\ntargets:")
    for name, ok, text in checks:
        click.echo(f"  {'ok    ' if ok else 'MISSED'} {name}: {text}")
    click.echo(f"\ndemo finished in {_duration(seconds, host_s)}: outputs in {out}; "
               "recordings:\n  "
               + "\n  ".join(str(p) for p in sorted(out.rglob("*.rrd"))))
    return [name for name, ok, _ in checks if not ok]


def _duration(seconds: float, host_s: float | None) -> str:
    """The demo's time, and in host figures when the figure was measured."""
    if host_s is None:
        return f"{seconds / 60:.1f} min (the host's figure not measured)"
    return f"{seconds / 60:.1f} min, {seconds / host_s:.0f} x the host's figure ({host_s:.2f} s)"


def _quick_time(seconds: float, host_s: float | None) -> tuple[str, bool, str]:
    """The quick demo's time against its target: in host figures, else in minutes."""
    if host_s is None:
        return ("quick demo time", seconds <= QUICK_MINUTES * 60,
                f"{_duration(seconds, host_s)} (target {QUICK_MINUTES:g} min)")
    return ("quick demo time", seconds <= QUICK_HOST_UNITS * host_s,
            f"{_duration(seconds, host_s)} (target {QUICK_HOST_UNITS} x)")


def _sync(out: Path) -> list[tuple[str, bool, str]]:
    from sync.sync_accuracy import TARGETS, sync_errors

    errors = sync_errors(out / "session_synced.h5", out / "session" / "truth.h5")
    return [(f"sync {key}", errors[key] <= target, f"{errors[key]:.4f} (target {target})")
            for key, target in TARGETS.items()]


def _fit(out: Path) -> list[tuple[str, bool, str]]:
    """The MSM fitted per fold, each beside a still surface on the same training presses
    (none with the generic pre-training)."""
    folds = len(json.loads((out / "splits.json").read_text())["folds"])   # this run's, no other
    files = [msm_dir(out, k) / "params.json" for k in range(folds)]
    if not all(f.is_file() for f in files):
        return []
    fits = [json.loads(f.read_text()) for f in files]
    ratios = [f["mean_distance_m"] / f["still_distance_m"] for f in fits]
    text = "; ".join(
        f"fold {k}: k_between {f['k_between']:.4g}, k_fixed {f['k_fixed']:.4g} N/m, "
        f"{f['mean_distance_m'] * 1e3:.3f} mm (still {f['still_distance_m'] * 1e3:.3f} mm, "
        f"{r:.0%})" + "".join(f", {b}" for b in f.get("at_bound", []))
        for k, (f, r) in enumerate(zip(fits, ratios, strict=True)))
    return [("MSM fitted per fold on its training presses", bool(fits)
             and max(ratios) <= MSM_VS_STILL, f"{text} (target {MSM_VS_STILL:.0%} each)")]


def variant_of(row: Row) -> str:
    """'tl' (fine-tuned from a generic model: the MSM prior's, or the moulds' for a curved
    lab), 'solid' (fine-tuned from a pre-training on the lab's fitted solid), 'msm' (the MSM
    model) or 'notl' (lab data from scratch), from the variant the run's checkpoint
    records."""
    v = Variant.from_dict(row.variant)
    if v.pretrained:
        return "solid" if v.pretrained.train_data == SOURCE_NAMES["solid"] else "tl"
    return "msm" if v.train_data == "MSM" else "notl"


FINE_TUNED = (("tl", "TL"), ("notl", "scratch"), ("solid", "TL from the solid"))


def _ld_mm(m: Metrics) -> float:
    """Mean L_d (mm); infinite where the predictions were not finite (no L_d)."""
    return math.inf if m.ld_mean_mm is None else m.ld_mean_mm


def _msm_model(scores: Scores) -> list[tuple[str, bool, str]]:
    """Each fold's MSM model on its own MSM test set, beside the references there."""
    runs = [r for r in scores.runs if variant_of(r) == "msm"]
    if not runs:
        return []
    ld, still, force, linear = [], [], [], []
    for r in runs:
        m, refs = r.metrics.all, r.references
        ld.append(_ld_mm(m))
        still.append(_ld_mm(refs[NOTHING_MOVES]))
        force.append(m.force_abs_n)
        linear.append(refs[FORCE_LINEAR].force_abs_n)
    return [("MSM models, mean L_d on their test sets",
             all(a <= MSM_VS_STILL * b for a, b in zip(ld, still, strict=True)),
             ", ".join(f"{a:.3f}" for a in ld) + " mm; nothing moves "
             + ", ".join(f"{b:.3f}" for b in still) + " mm"),
            ("MSM models, force error", all(a < b for a, b in zip(force, linear, strict=True)),
             ", ".join(f"{a:.3f}" for a in force) + " N; linear "
             + ", ".join(f"{b:.3f}" for b in linear) + " N")]


def _ld_gain(row: RunRow | LumpPart) -> float:
    """A row's mean L_d gain over the best reference; -100 % where predictions were not
    finite (no gain to report)."""
    gain = row.gain.ld_gain
    return -1.0 if gain is None else gain


# A lump's parts, by their names in the document (LumpRow.parts), in words
LUMP_WORDS = dict(zip(LUMP_PARTS, ("over the lump", "away from the lump"), strict=True))


def _over_lump(scores: Scores) -> list[tuple[str, bool, str]]:
    """Where eval split the test presses by a lump: TL and scratch, every fold that has test
    presses there, over the lump and away from it, beside the best reference there."""
    checks = []
    for part, where in LUMP_WORDS.items():
        for variant, name in FINE_TUNED:
            folds = sorted(((r.fold, r.lump.parts()[part]) for r in scores.runs
                            if variant_of(r) == variant and r.lump),
                           key=lambda fold_rows: fold_rows[0])
            held = [(k, rows) for k, rows in folds if rows]
            empty = [str(k) for k, rows in folds if not rows]
            if not folds:
                continue
            text = ", ".join(f"fold {k}: {_ld_gain(rows):+.0%} ({rows.metrics.n} "
                             "examples)" for k, rows in held)
            text += f"; no test press there in fold(s) {', '.join(empty)}" if empty else ""
            checks.append((f"{name} {where}: mean L_d below the best reference",
                           bool(held) and min(_ld_gain(rows) for _, rows in held) >= FOLD_GAIN,
                           f"{text} (target {FOLD_GAIN:.0%} each)"))
    return checks


def pooled(rows: list[Metrics], value: Callable[[Metrics], float]) -> float:
    """``value`` over the examples of every row (each weighted by its count)."""
    return sum(value(m) * m.n for m in rows) / sum(m.n for m in rows)


def _force_over_lump(scores: Scores) -> list[tuple[str, bool, str]]:
    """Each fine-tuned variant's force error over a lump against away from it, pooled over
    the folds: a haptic trainer's hand feels the lump's error most."""
    checks = []
    for variant, name in FINE_TUNED:
        rows = [r.lump for r in scores.runs if variant_of(r) == variant and r.lump]
        over = [p.over.metrics for p in rows if p.over]
        away = [p.away.metrics for p in rows if p.away]
        if not over or not away:
            continue
        f_over, f_away = (pooled(m, lambda m: m.force_abs_n) for m in (over, away))
        checks.append((f"{name}: the force's error over the lump against away from it",
                       f_over <= FORCE_OVER_AWAY * f_away,
                       f"{f_over:.3f} against {f_away:.3f} N ({f_over / f_away:.2f} x; target "
                       f"<= {FORCE_OVER_AWAY:g} x)"))
    return checks


def _solid_over_lump(scores: Scores) -> list[tuple[str, bool, str]]:
    """With --pretraining solid and a lump: TL from the solid against TL from the shipped
    model over the lump, pooled over the folds with test presses there (the same examples)."""
    over = {v: [r.lump.over.metrics for r in scores.runs if variant_of(r) == v
                and r.lump and r.lump.over] for v in ("tl", "solid")}
    if not over["tl"] or not over["solid"]:
        return []

    ld = {v: pooled(rows, _ld_mm) for v, rows in over.items()}
    force = {v: pooled(rows, lambda m: m.force_abs_n) for v, rows in over.items()}
    gain = 1 - ld["solid"] / ld["tl"]
    return [("TL from the solid over the lump, against TL from the shipped model",
             gain >= SOLID_OVER_LUMP,
             f"mean L_d {ld['solid']:.4f} against {ld['tl']:.4f} mm ({gain:+.0%}), force "
             f"{force['solid']:.3f} against {force['tl']:.3f} N (target "
             f"{SOLID_OVER_LUMP:.0%} lower L_d)")]


def _fine_tuned(scores: Scores) -> list[tuple[str, bool, str]]:
    checks = []
    by = {v: sorted((r for r in scores.runs if variant_of(r) == v), key=lambda r: r.fold)
          for v, _ in FINE_TUNED}
    for variant, name in FINE_TUNED:
        if not by[variant]:
            continue
        gains = [_ld_gain(r) for r in by[variant]]
        force = [r.metrics.all.force_abs_n / r.references[FORCE_LINEAR].force_abs_n
                 for r in by[variant]]
        checks.append((f"{name}: mean L_d below the best reference in every fold",
                       min(gains, default=0) >= FOLD_GAIN,
                       "gains " + ", ".join(f"{g:+.0%}" for g in gains)
                       + f" (target {FOLD_GAIN:.0%} each)"))
        checks.append((f"{name}: force error against the linear reference",
                       max(force, default=1) <= FORCE_VS_LINEAR,
                       "ratios " + ", ".join(f"{f:.2f}" for f in force)
                       + f" (target <= {FORCE_VS_LINEAR})"))
    tl = [_ld_mm(r.metrics.all) for r in by["tl"]]
    scratch = [_ld_mm(r.metrics.all) for r in by["notl"]]
    if tl and len(tl) == len(scratch):
        n = [r.metrics.all.n for r in by["tl"]]
        pooled = 1 - sum(a * k for a, k in zip(tl, n, strict=True)) / sum(
            b * k for b, k in zip(scratch, n, strict=True))
        better = sum(a < b for a, b in zip(tl, scratch, strict=True))
        checks.append(("transfer learning, pooled over folds",
                       pooled >= TL_CUT and better >= len(tl) - 1,
                       f"mean L_d {pooled:.0%} below scratch trained as long (target "
                       f"{TL_CUT:.0%}; the paper's 23 %), better in {better} of {len(tl)} "
                       "folds"))
    return checks


def _intervals(scores: Scores) -> list[tuple[str, bool, str]]:
    """Each fine-tuned variant's intervals on its test presses against the targets: pooled
    over its folds, each level's share inside its band; each run's radius and near/far."""
    runs = sorted((r for r in scores.runs if variant_of(r) in ("tl", "notl")),
                  key=lambda r: (variant_of(r), r.fold))
    if not runs:
        return []
    held = [(r, r.intervals) for r in runs if r.intervals is not None]
    if len(held) < len(runs):
        return [("intervals", False, "absent (retrain): "
                 + ", ".join(r.run for r in runs if r.intervals is None))]
    name = {r.run: f"{'TL' if variant_of(r) == 'tl' else 'scratch'} {r.fold}" for r in runs}
    pooled = [("TL" if variant_of(r) == "tl" else "scratch", v)
              for r in sorted(scores.overall, key=variant_of, reverse=True)
              if variant_of(r) in ("tl", "notl") and r.intervals
              for v in r.intervals.levels]
    ratio = [(name[r.run], doc.radius_to_ld) for r, doc in held]
    near = [(name[r.run], doc.by_distance) for r, doc in held]
    return [
        _pooled_check(pooled, "test points", lambda v: (v.coverage, v.band)),
        _pooled_check(pooled, "changes of force", lambda v: (v.force_coverage, v.force_band)),
        ("intervals: mean 90 % radius against mean L_d",
         all(v is not None and v <= RADIUS_VS_LD for _, v in ratio),
         _per_run(ratio, lambda v: "unbounded" if v is None else f"{v:.2f}x")
         + f" (target <= {RADIUS_VS_LD:g}x)"),
        ("intervals: points beside the tip's path get larger 90 % radii than far ones",
         all(_falls(bins) for _, bins in near),
         _per_run(near, lambda b: " > ".join(
             "–" if x.mean_radius_mm is None else f"{x.mean_radius_mm:.2f}" for x in b)
             + " mm")),
    ]


Share = Callable[[IntervalLevel], tuple[float, list[float] | None]]   # a share and its band


def _pooled_check(pooled: list[tuple[str, IntervalLevel]], what: str, share: Share
                  ) -> tuple[str, bool, str]:
    """One score's pooled shares (each variant's levels) against their bands."""
    return (f"intervals: {what} inside their 80/90/95 % intervals, pooled over the folds",
            bool(pooled) and all(_inside(*share(v)) for _, v in pooled),
            _per_run(pooled, lambda v: _in_band(*share(v)))
            + " (target: inside the range re-drawn calibration presses give by chance)")


def _inside(share: float, band: list[float] | None) -> bool:
    """Whether a share lies in its band [low, high] (False where none was measured)."""
    return band is not None and band[0] <= share <= band[1]


def _in_band(share: float, band: list[float] | None) -> str:
    """'90.4% (86-92)': a share with the range it falls in by chance."""
    return f"{share:.1%} " + ("(no band: re-run eval)" if band is None
                              else f"({band[0] * 100:.0f}-{band[1] * 100:.0f})")


def _per_run(items: list[tuple[str, Any]], show: Callable[[Any], str]) -> str:
    """'name: a/b/c; ...': each run's values shown in turn."""
    by: dict[str, list[str]] = {}
    for name, value in items:
        by.setdefault(name, []).append(show(value))
    return "; ".join(f"{name}: {'/'.join(v)}" for name, v in by.items())


def _falls(bins: list[DistanceBin]) -> bool:
    """Whether the nearest distance bin's mean radius exceeds the farthest's."""
    radii = [b.mean_radius_mm for b in bins]
    first, last = (radii[0], radii[-1]) if radii else (None, None)
    return len(radii) > 1 and first is not None and last is not None and first > last


def scarcity_rows(out: Path) -> list[ScarcityRow]:
    """The data-scarcity rows of every fold the demo studied (``scarcity/fold<K>.json``)."""
    files = [p for p in sorted((out / "scarcity").glob("fold*.json")) if p.suffixes == [".json"]]
    return [r for p in files
            for r in Scores.from_json(json.loads(p.read_text())).scarcity or []]


def _scarcity_ld(row: ScarcityRow) -> float | None:
    return row.ld_mean_mm


def _scarcity(out: Path) -> list[tuple[str, bool, str]]:
    from train.evaluation.scarcity import curve

    rows = scarcity_rows(out)
    if not rows:
        return []
    groups, tl = curve(rows, "TL", _scarcity_ld)
    _, scratch = curve(rows, "no TL", _scarcity_ld)
    _, near = curve(rows, NEAREST_PRESS, _scarcity_ld)
    cuts = [1 - a / b for a, b in zip(tl, scratch, strict=True)]
    if not cuts:                                  # runs without --init: no TL to compare
        return []
    text = "; ".join(f"{g} press{'es' if g > 1 else ''}: TL {a:.3f}, scratch {b:.3f}, "
                     f"nearest press {c:.3f} mm ({d:+.0%})"
                     for g, a, b, c, d in zip(groups, tl, scratch, near, cuts, strict=True))
    return [("transfer learning with few presses (scarcity study)",
             min(cuts) >= SCARCITY_CUT, text + f" (target {SCARCITY_CUT:.0%} each)"),
            *_scarce_intervals(rows)]


def _scarce_intervals(rows: list[ScarcityRow]) -> list[tuple[str, bool, str]]:
    """The intervals of the scarcity study's models with the fewest training presses: the
    points' and the force's share inside their 90 % intervals, each inside the range its
    fold's re-drawn calibration presses give by chance (none where no row says; a model's
    row with one share and not the other misses it, naming the missing one)."""
    fewest = min(r.groups for r in rows)
    kept = [(r, r.shares.by_score()) for r in rows
            if r.groups == fewest and r.shares is not None]
    shares = [(r, what, share, band) for r, scores in kept
              if any(value is not None for value, _ in scores.values())   # intervals kept
              for what, (share, band) in scores.items()]
    if not shares:
        return []
    ok = all(share is not None and _inside(share, band) for _, _, share, band in shares)
    text = "; ".join(f"fold {r.fold} {r.predictor}: {what} "
                     + ("share missing" if share is None else _in_band(share, band))
                     for r, what, share, band in shares)
    return [(f"intervals with {fewest} training press{'es' if fewest > 1 else ''} (scarcity "
             "study), 90 %", ok, text + " (target: inside the range re-drawn calibration "
             "presses give by chance)")]

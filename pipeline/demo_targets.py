"""The demo's summary: every result beside its target, so a miss is impossible to overlook.

Targets (the references are the predictors that learn nothing, scored on the same test
examples, :mod:`train.evaluation.references`):

- sync against the twin's truth (:data:`sync.sync_accuracy.TARGETS`);
- the MSM fitted per fold at most half as far from that fold's training presses as a still
  surface;
- the MSM-trained model on its own test set: mean L_d at most half of "nothing moves", force
  error below the linear reference;
- fine-tuned with transfer learning (TL) and from scratch: mean L_d at least 30 % below the
  best reference in every fold; force error at most half the linear reference's;
- TL: pooled mean L_d at least 20 % below scratch, better in all folds but one; in the
  data-scarcity study, at least 30 % below scratch at every number of training presses shown;
- the quick demo under 5 minutes.
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from data_schema.json_docs import FORCE_LINEAR, NEAREST_PRESS, NOTHING_MOVES, validate_metrics
from pipeline.demo_plan import msm_dir

FOLD_GAIN = 0.30        # every fold: mean L_d this far below the best reference
TL_CUT = 0.20           # pooled: TL this far below scratch
SCARCITY_CUT = 0.30     # scarcity study: TL this far below scratch at each size
FORCE_VS_LINEAR = 0.5   # force error at most this fraction of the linear reference's
MSM_VS_STILL = 0.5      # MSM model (and the fit) at most this fraction of a still surface's
QUICK_MINUTES = 5.0


def summary(out: Path, seconds: float, quick: bool) -> list[str]:
    """Print every result against its target; return the names of the targets missed."""
    checks: list[tuple[str, bool, str]] = []
    checks += _sync(out)
    checks += _fit(out)
    click.echo("\n" + (out / "metrics.md").read_text())
    doc = validate_metrics(out / "metrics.json")
    checks += _msm_model(doc)
    checks += _fine_tuned(doc)
    checks += _scarcity(out)
    if quick:
        checks.append(("quick demo time", seconds <= QUICK_MINUTES * 60,
                       f"{seconds / 60:.1f} min (target {QUICK_MINUTES:g})"))
    click.echo("\ntargets:")
    for name, ok, text in checks:
        click.echo(f"  {'ok    ' if ok else 'MISSED'} {name}: {text}")
    click.echo(f"\ndemo finished in {seconds / 60:.1f} min: outputs in {out}; recordings:\n  "
               + "\n  ".join(str(p) for p in sorted(out.rglob("*.rrd"))))
    return [name for name, ok, _ in checks if not ok]


def _sync(out: Path) -> list[tuple[str, bool, str]]:
    from sync.sync_accuracy import TARGETS, sync_errors

    errors = sync_errors(out / "session_synced.h5", out / "session" / "truth.h5")
    return [(f"sync {key}", errors[key] <= target, f"{errors[key]:.4f} (target {target})")
            for key, target in TARGETS.items()]


def _fit(out: Path) -> list[tuple[str, bool, str]]:
    """The MSM fitted per fold, each beside a still surface on the same training presses."""
    folds = len(json.loads((out / "splits.json").read_text())["folds"])   # this run's, no other
    fits = [json.loads((msm_dir(out, k) / "params.json").read_text()) for k in range(folds)]
    ratios = [f["mean_distance_m"] / f["still_distance_m"] for f in fits]
    text = "; ".join(
        f"fold {k}: k_between {f['k_between']:.4g}, k_fixed {f['k_fixed']:.4g} N/m, "
        f"{f['mean_distance_m'] * 1e3:.3f} mm (still {f['still_distance_m'] * 1e3:.3f} mm, "
        f"{r:.0%})" + "".join(f", {b}" for b in f.get("at_bound", []))
        for k, (f, r) in enumerate(zip(fits, ratios, strict=True)))
    return [("MSM fitted per fold on its training presses", bool(fits)
             and max(ratios) <= MSM_VS_STILL, f"{text} (target {MSM_VS_STILL:.0%} each)")]


def variant_of(run: dict) -> str:
    """'tl' (fine-tuned), 'msm' (the MSM model) or 'notl' (lab data from scratch), from the
    variant the run's checkpoint records."""
    v = run["variant"]
    return "tl" if v["pretrained"] else "msm" if v["train_data"] == "MSM" else "notl"


def _msm_model(doc: dict) -> list[tuple[str, bool, str]]:
    """Each fold's MSM model on its own MSM test set, beside the references there."""
    runs = [r for r in doc["runs"] if variant_of(r) == "msm"]
    if not runs:
        return []
    ld, still, force, linear = [], [], [], []
    for r in runs:
        m, refs = r["metrics"]["all"], r["references"]
        ld.append(m["ld_mean_mm"] if m["ld_mean_mm"] is not None else float("inf"))
        still.append(refs[NOTHING_MOVES]["ld_mean_mm"])
        force.append(m["force_abs_n"])
        linear.append(refs[FORCE_LINEAR]["force_abs_n"])
    return [("MSM models, mean L_d on their test sets",
             all(a <= MSM_VS_STILL * b for a, b in zip(ld, still, strict=True)),
             ", ".join(f"{a:.3f}" for a in ld) + " mm; nothing moves "
             + ", ".join(f"{b:.3f}" for b in still) + " mm"),
            ("MSM models, force error", all(a < b for a, b in zip(force, linear, strict=True)),
             ", ".join(f"{a:.3f}" for a in force) + " N; linear "
             + ", ".join(f"{b:.3f}" for b in linear) + " N")]


def _fine_tuned(doc: dict) -> list[tuple[str, bool, str]]:
    checks = []
    by = {v: sorted((r for r in doc["runs"] if variant_of(r) == v), key=lambda r: r["fold"])
          for v in ("tl", "notl")}
    for variant, name in (("tl", "TL"), ("notl", "scratch")):
        gains = [r["gain"]["ld_gain"] if r["gain"]["ld_gain"] is not None else -1.0
                 for r in by[variant]]                      # -100 %: predictions not finite
        force = [r["metrics"]["all"]["force_abs_n"]
                 / r["references"][FORCE_LINEAR]["force_abs_n"] for r in by[variant]]
        checks.append((f"{name}: mean L_d below the best reference in every fold",
                       min(gains, default=0) >= FOLD_GAIN,
                       "gains " + ", ".join(f"{g:+.0%}" for g in gains)
                       + f" (target {FOLD_GAIN:.0%} each)"))
        checks.append((f"{name}: force error against the linear reference",
                       max(force, default=1) <= FORCE_VS_LINEAR,
                       "ratios " + ", ".join(f"{f:.2f}" for f in force)
                       + f" (target <= {FORCE_VS_LINEAR})"))
    tl = [r["metrics"]["all"]["ld_mean_mm"] for r in by["tl"]]
    scratch = [r["metrics"]["all"]["ld_mean_mm"] for r in by["notl"]]
    if tl and len(tl) == len(scratch):
        n = [r["metrics"]["all"]["n"] for r in by["tl"]]
        pooled = 1 - sum(a * k for a, k in zip(tl, n, strict=True)) / sum(
            b * k for b, k in zip(scratch, n, strict=True))
        better = sum(a < b for a, b in zip(tl, scratch, strict=True))
        checks.append(("transfer learning, pooled over folds",
                       pooled >= TL_CUT and better >= len(tl) - 1,
                       f"mean L_d {pooled:.0%} below scratch (target {TL_CUT:.0%}; paper "
                       f"23%), better in {better} of {len(tl)} folds"))
    return checks


def scarcity_rows(out: Path) -> list[dict]:
    """The data-scarcity rows of every fold the demo studied (``scarcity/fold<K>.json``)."""
    files = [p for p in sorted((out / "scarcity").glob("fold*.json")) if p.suffixes == [".json"]]
    return [r for p in files for r in json.loads(p.read_text())["scarcity"]]


def _scarcity(out: Path) -> list[tuple[str, bool, str]]:
    from train.evaluation.scarcity import curve

    rows = scarcity_rows(out)
    if not rows:
        return []
    groups, tl = curve(rows, "TL", "ld_mean_mm")
    _, scratch = curve(rows, "no TL", "ld_mean_mm")
    _, near = curve(rows, NEAREST_PRESS, "ld_mean_mm")
    cuts = [1 - a / b for a, b in zip(tl, scratch, strict=True)]
    if not cuts:                                  # runs without --init: no TL to compare
        return []
    text = "; ".join(f"{g} press{'es' if g > 1 else ''}: TL {a:.3f}, scratch {b:.3f}, "
                     f"nearest press {c:.3f} mm ({d:+.0%})"
                     for g, a, b, c, d in zip(groups, tl, scratch, near, cuts, strict=True))
    return [("transfer learning with few presses (scarcity study)",
             min(cuts) >= SCARCITY_CUT, text + f" (target {SCARCITY_CUT:.0%} each)")]

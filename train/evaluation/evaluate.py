"""Evaluation on a fold's test split: the paper's Table 2 metrics, per set and overall.

Per example: L_d, the mean over points of the distance between predicted and true deformed
points, and its max over points; the force error |dF_pred - dF|. Per run and set (single,
multi, both): force MSE, force absolute error mean +- sd, mean L_d mean +- sd and max L_d mean
+- sd over examples (mm). Runs of one variant (all its fields,
:class:`train.training.variant.Variant`, not its label) are pooled over their folds, and the
spread of the per-fold means is given beside. Every run and label is scored beside the
no-learning references (:mod:`train.evaluation.references`) on the same test examples, with its
gain over the best of them: a model that does not beat them has learned nothing worth shipping.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from core.errors import BadInput
from data_schema.states import example_groups
from train.data import (
    SETS,
    Batch,
    StateTensors,
    example_pairs,
    load_manifest,
    load_states,
    make_batch,
    role_examples,
)
from train.evaluation.coverage import Coverage, absent, coverage, coverage_doc, coverage_table
from train.evaluation.coverage_band import band, counts_of, redrawn_counts
from train.evaluation.lump import PARTS, Lump, press_xy
from train.evaluation.references import DISPLACEMENT, FORCE, NAMES, References, best_reference
from train.intervals.table import IntervalTable
from train.model.normalise import Normaliser
from train.model.si_units import BatchPrediction, distances, predict
from train.training.calibrate import Residuals, joined, residuals
from train.training.checkpoint import load_checkpoint, model_from
from train.training.variant import Variant, recorded_variant, source_name

PLACE_M = 0.002            # m: without place ids, test presses this close are one place


@dataclass
class ExampleErrors:
    """Per test example of one run."""

    set: np.ndarray          # (E,) "single" | "multi"
    ld_mean: np.ndarray      # (E,) m
    ld_max: np.ndarray       # (E,) m
    force_err: np.ndarray    # (E,) N, predicted - true


@dataclass
class LoadedRun:
    """A run's best model with the data and test examples of its fold."""

    model: torch.nn.Module
    norm: Normaliser
    states: StateTensors
    test: dict[str, np.ndarray]      # set -> example ids
    meta: dict
    splits: Path
    train: dict[str, np.ndarray]     # set -> the training example ids of the run's fold
    intervals: IntervalTable | None = None   # calibrated on the fold's validation presses


def load_run(run_dir: Path, device: str = "cpu") -> LoadedRun:
    """The best checkpoint of ``run_dir``, its states and its fold's test examples."""
    state = load_checkpoint(run_dir / "best.pt", device)
    meta = state["meta"]
    data, splits = Path(meta["data"]["file"]), Path(meta["splits"])
    for p in (data, splits):
        if not p.is_file():
            raise BadInput(run_dir / "best.pt", f"its data {p} is gone")
    doc = load_manifest(splits, data)
    model, norm = model_from(state, device)
    opts = meta["options"]
    return LoadedRun(model, norm, load_states(data).to(device),
                     role_examples(doc, opts["fold"], "test"), meta, splits,
                     role_examples(doc, opts["fold"], "train", data, opts["train_groups"]),
                     IntervalTable.from_dict(state["intervals"]) if "intervals" in state
                     else None)


def on_lab(state: dict, data: Path, splits: Path, fold: int,
           device: str = "cpu") -> LoadedRun:
    """A model trained elsewhere (``state``: a checkpoint, as the generic model) on a lab's
    fold: its test examples as they are (zero-shot: the model's own normaliser), and the
    fold's training examples for the references that fit on them."""
    doc = load_manifest(splits, data)
    model, norm = model_from(state, device)
    return LoadedRun(model, norm, load_states(data).to(device),
                     role_examples(doc, fold, "test"), {"options": {"fold": fold}}, splits,
                     role_examples(doc, fold, "train", data))


@torch.no_grad()
def example_errors(run: LoadedRun, transform: Callable[[Batch], Batch] | None = None,
                   predictor: Callable[[Batch], BatchPrediction] | None = None, batch: int = 64
                   ) -> tuple[ExampleErrors, list[tuple[Batch, BatchPrediction]]]:
    """Errors on the test examples, each batch first moved by ``transform`` (a robustness
    test) and predicted by ``predictor`` (another precision; default: the model as it is);
    and a few (batch, prediction) pairs for the recording."""
    predictor = predictor or (lambda b: predict(run.model, run.norm, b))
    cols: dict[str, list] = {"set": [], "ld_mean": [], "ld_max": [], "force_err": []}
    shown: list[tuple[Batch, BatchPrediction]] = []
    for name in SETS:
        pairs = run.states.pairs[name][torch.as_tensor(run.test[name], dtype=torch.long)]
        for rows in pairs.split(batch):
            b = make_batch(run.states, rows)
            b = transform(b) if transform else b
            p = predictor(b)
            d = distances(p, b)
            cols["set"] += [name] * len(rows)
            cols["ld_mean"].append((d.sum(1) / b.mask.sum(1).clamp(min=1)).float().cpu().numpy())
            cols["ld_max"].append(d.amax(1).float().cpu().numpy())
            cols["force_err"].append((p.dforce - b.dforce).float().cpu().numpy())
            if len(shown) < 2:
                shown.append((b, p))
    if not cols["ld_mean"]:
        raise BadInput(run.splits, f"fold {run.meta['options']['fold']} has no test example")
    errs = ExampleErrors(np.array(cols["set"]), *(np.concatenate(cols[k]).astype(np.float64)
                                                  for k in ("ld_mean", "ld_max", "force_err")))
    return errs, shown


def reference_errors(run: LoadedRun) -> dict[str, ExampleErrors]:
    """The errors of each no-learning reference on the run's test examples, fitted on the
    training examples of its fold (the same subset the run trained on)."""
    refs = References(run.states, example_pairs(run.states, run.train))
    return {name: example_errors(run, predictor=lambda b, n=name: refs.predict(n, b))[0]
            for name in NAMES}


def test_errors(run_dir: Path, device: str = "cpu"
                ) -> tuple[ExampleErrors, LoadedRun, list[tuple[Batch, BatchPrediction]]]:
    """Errors of a run's best model on its fold's test examples, the run, and a few
    (batch, prediction) pairs for the recording."""
    run = load_run(run_dir, device)
    errs, shown = example_errors(run)
    return errs, run, shown


def fold_coverage(run: LoadedRun, run_dir: Path, keep: np.ndarray | None = None,
                  quiet: bool = False) -> Coverage | None:
    """The coverage of a run's intervals on its fold's test examples (those of ``keep``
    only, a mask in :func:`example_errors`' order, where given); None, said in one line
    unless ``quiet``, where its checkpoint keeps none or ``keep`` keeps nothing."""
    if run.intervals is None:
        if not quiet:
            absent(str(run_dir))
        return None
    pairs = example_pairs(run.states, run.test)
    if keep is not None:
        if not keep.any():
            return None
        pairs = pairs[torch.as_tensor(keep)]
    return coverage(run.intervals, residuals(run.model, run.norm, run.states, pairs))


def coverage_and_band(run: LoadedRun, run_dir: Path
                      ) -> tuple[Coverage | None, np.ndarray | None]:
    """:func:`fold_coverage` of all the fold's test examples and :func:`fold_redraws`, the
    test examples predicted once; (None, None), said in one line, where the run keeps no
    intervals."""
    if run.intervals is None:
        absent(str(run_dir))
        return None, None
    test = residuals(run.model, run.norm, run.states, example_pairs(run.states, run.test))
    return coverage(run.intervals, test), fold_redraws(run, test)


def fold_redraws(run: LoadedRun, test: Residuals) -> np.ndarray | None:
    """The coverage of a run's fold with its calibration presses re-drawn among its held-out
    (validation and test) presses (:func:`~train.evaluation.coverage_band.redrawn_counts`),
    from the residuals of its ``test`` examples and of its validation examples; None where
    no press would be left to score."""
    doc = json.loads(run.splits.read_text())
    fold = run.meta["options"]["fold"]
    groups = example_groups(run.meta["data"]["file"], doc["group_by"])
    val = role_examples(doc, fold, "val")
    held = joined([residuals(run.model, run.norm, run.states, example_pairs(run.states, val)),
                   test])
    press = np.concatenate([groups[s][ids[s]] for ids in (val, run.test) for s in SETS])
    return redrawn_counts(held, press, run.intervals.presses, fold)


def metrics(e: ExampleErrors) -> dict[str, dict[str, float | None]]:
    """Table 2 metrics for single, multi and both (mm, N, N^2); L_d is None for a predictor
    that moves no point (the linear force reference)."""
    out = {}
    for name, keep in (("single", e.set == "single"), ("multi", e.set == "multi"),
                       ("all", np.ones(len(e.set), bool))):
        if not keep.any():
            continue
        fe = e.force_err[keep]
        out[name] = {"n": int(keep.sum()), "force_mse_n2": float(np.mean(fe**2)),
                     "force_abs_n": float(np.mean(np.abs(fe))),
                     "force_abs_sd_n": float(np.std(np.abs(fe)))}
        for key, values in (("ld_mean", e.ld_mean[keep]), ("ld_max", e.ld_max[keep])):
            finite = bool(np.isfinite(values).all())
            out[name][f"{key}_mm"] = float(np.mean(values) * 1e3) if finite else None
            out[name][f"{key}_sd_mm"] = float(np.std(values) * 1e3) if finite else None
    return out


def subset(e: ExampleErrors, keep: np.ndarray) -> ExampleErrors:
    """The examples of ``keep`` (a mask)."""
    return ExampleErrors(e.set[keep], e.ld_mean[keep], e.ld_max[keep], e.force_err[keep])


def pool(errors: list[ExampleErrors]) -> ExampleErrors:
    """All examples of several runs (folds) as one set."""
    return ExampleErrors(*(np.concatenate([getattr(e, k) for e in errors])
                           for k in ("set", "ld_mean", "ld_max", "force_err")))


def gains(model: dict, refs: dict[str, dict]) -> dict:
    """A model's mean L_d and force error against the best reference of each (on the "all"
    metrics): the reference's name and value, and the model's relative gain (positive: the
    model is better; 0.3 = 30 % lower error; None where either value is missing, as for a
    model whose predictions are not finite)."""
    out = {}
    for what, key, unit, names in (("ld", "ld_mean_mm", "mm", DISPLACEMENT),
                                   ("force", "force_abs_n", "n", FORCE)):
        name, ref = best_reference(refs, key, names)
        value = model.get(key)
        gain = None if value is None or ref is None else (1 - value / ref if ref else 0.0)
        out.update({f"{what}_reference": name, f"{what}_reference_{unit}": ref,
                    f"{what}_gain": gain})
    return out


def evaluate_runs(run_dirs: list[Path], device: str = "cpu", lump: Lump | None = None
                  ) -> dict:
    """Metrics per run and per variant (pooled over its folds, with the spread over folds),
    each beside the no-learning references on the same test examples, and the gain over the
    best of them; with a ``lump``, the same over it and away from it
    (:mod:`train.evaluation.lump`). Runs are pooled only where their whole :class:`Variant`
    and test set are the same (two variants may share a label)."""
    runs, groups = [], {}
    for run_dir in run_dirs:
        run = load_run(run_dir, device)
        errs = example_errors(run)[0]
        refs = reference_errors(run)
        m = metrics(errs)
        ref_m = {n: metrics(e)["all"] for n, e in refs.items()}
        variant, test_set = recorded_variant(run.meta), source_name(run.meta["data"]["file"])
        cover, redrawn = coverage_and_band(run, run_dir)
        runs.append({"run": str(run_dir), "label": variant.label, "variant": variant.to_dict(),
                     "fold": run.meta["options"]["fold"], "test_set": test_set, "metrics": m,
                     "references": ref_m, "gain": gains(m["all"], ref_m),
                     "intervals": _intervals(cover, m, run.intervals, redrawn)})
        parts = None
        if lump is not None:
            over = lump.over(press_xy(run.states, example_pairs(run.states, run.test)))
            parts = {"over": over, "away": ~over}
            covers = {k: fold_coverage(run, run_dir, keep, quiet=True)
                      for k, keep in parts.items()}
            runs[-1]["lump"] = _lump_row(lump, errs, refs, parts, covers)
            parts = (parts, covers)
        groups.setdefault((variant, test_set), []).append((errs, refs, runs[-1], cover,
                                                           parts, redrawn))
    return {"runs": runs, "overall": [_pooled(v, test_set, items, lump)
                                      for (v, test_set), items in groups.items()]}


def _lump_row(lump: Lump, errs: ExampleErrors, refs: dict[str, ExampleErrors],
              parts: dict[str, np.ndarray], covers: dict[str, Coverage | None]) -> dict:
    """A row's ``lump``: the lump, and per part (over, away) the model's "all" metrics, the
    references' on the same examples, the gain and the intervals' coverage; a part with no
    test example is null."""
    doc: dict = lump.as_doc()
    for part in PARTS:
        keep = parts[part]
        if not keep.any():
            doc[part] = None
            continue
        m = metrics(subset(errs, keep))["all"]
        ref_m = {n: metrics(subset(e, keep))["all"] for n, e in refs.items()}
        cover = covers[part]
        doc[part] = {"metrics": m, "references": ref_m, "gain": gains(m, ref_m),
                     "intervals": None if cover is None else coverage_doc(cover,
                                                                          m["ld_mean_mm"])}
    return doc


def _intervals(cover: Coverage | None, m: dict, table: IntervalTable | None = None,
               redrawn: np.ndarray | None = None) -> dict | None:
    """A row's intervals: their coverage, with the band it is judged against where the
    re-drawn calibrations' ``redrawn`` counts are given (and, for a run, the calibration
    they stand on); None where they are absent."""
    if cover is None:
        return None
    doc = coverage_doc(cover, m["all"]["ld_mean_mm"],
                       None if redrawn is None else band(counts_of(cover), redrawn))
    if table is not None:
        doc["calibration"] = {"presses": table.presses, "examples": table.examples}
    return doc


def _pooled(variant: Variant, test_set: str, items: list[tuple], lump: Lump | None = None
            ) -> dict:
    """The overall row of one variant on one test set: its runs' (errors, reference errors,
    run row, coverage, and with a ``lump`` the parts' masks and coverages) pooled over their
    folds."""
    pooled = metrics(pool([e for e, *_ in items]))
    ref_m = {n: metrics(pool([r[n] for _, r, *_ in items]))["all"] for n in NAMES}
    cover = _sum_coverage([item[3] for item in items])
    fold_ld = [r["metrics"]["all"]["ld_mean_mm"] for _, _, r, *_ in items]
    fold_ld = [v for v in fold_ld if v is not None] or [0.0]
    row = {"label": variant.label, "variant": variant.to_dict(),
            "test_set": test_set, "folds": len(items),
            "fold_ids": [r["fold"] for _, _, r, *_ in items],
            "metrics": pooled, "fold_ld_mean_sd_mm": float(np.std(fold_ld)),
            "references": ref_m, "gain": gains(pooled["all"], ref_m),
            "folds_not_beating_references": [
                r["fold"] for _, _, r, *_ in items if not _beats(r["gain"]["ld_gain"])],
            "intervals": _intervals(cover, pooled, redrawn=_summed([item[5] for item in items]))}
    if lump is not None:
        parts = {k: np.concatenate([item[4][0][k] for item in items]) for k in PARTS}
        covers = {k: _sum_coverage([item[4][1][k] for item in items if item[4][0][k].any()])
                  for k in PARTS}
        refs = {n: pool([r[n] for _, r, *_ in items]) for n in NAMES}
        row["lump"] = _lump_row(lump, pool([e for e, *_ in items]), refs, parts, covers)
    return row


def _sum_coverage(covers: list[Coverage | None]) -> Coverage | None:
    """Coverages pooled; None where any is missing (or there is none)."""
    if not covers or None in covers:
        return None
    return sum(covers[1:], covers[0])


def _summed(redrawn: list[np.ndarray | None]) -> np.ndarray | None:
    """Folds' re-drawn counts added draw by draw; None where any is missing."""
    if not redrawn or any(r is None for r in redrawn):
        return None
    return np.sum(redrawn, axis=0)


def shown_name(row: dict, rows: list[dict]) -> str:
    """A run's or variant's name as shown: its label, or its full name where another variant
    among ``rows`` has the same label."""
    if any(r["label"] == row["label"] and r["variant"] != row["variant"] for r in rows):
        return Variant.from_dict(row["variant"]).full_name
    return row["label"]


def _beats(gain: float | None) -> bool:
    return gain is not None and gain > 0


def not_beating(result: dict) -> list[str]:
    """One line per variant whose pooled mean L_d or force error does not beat the best
    reference (what ``pipeline eval --strict`` fails on)."""
    lines = []
    for row in result["overall"]:
        g = row["gain"]
        for what, gain, ref in (("mean L_d", g["ld_gain"], g["ld_reference"]),
                                ("force error", g["force_gain"], g["force_reference"])):
            if not _beats(gain):
                worse = "not finite" if gain is None else f"{-gain:.0%} worse"
                lines.append(f"{shown_name(row, result['overall'])} on {row['test_set']}: "
                             f"{what} does not beat "
                             f"'{ref}' ({worse})")
    return lines


def _pct(gain: float | None) -> str:
    return "–" if gain is None else f"{gain:+.0%}"


def _num(value: float | None) -> str:
    return "–" if value is None else f"{value:.3f}"


def _cell(m: dict, key: str, sd: str) -> str:
    """'mean ± sd' to 2 decimals, or '–' where the predictor has no such value."""
    return "–" if m.get(key) is None else f"{m[key]:.2f} ± {m[sd]:.2f}"


def _row(name: str, test_set: str, m: dict, gain: str, folds: str) -> str:
    return (f"| {name} | {test_set} | {m['force_mse_n2']:.3g} | "
            f"{_cell(m, 'force_abs_n', 'force_abs_sd_n')} | "
            f"{_cell(m, 'ld_mean_mm', 'ld_mean_sd_mm')} | "
            f"{_cell(m, 'ld_max_mm', 'ld_max_sd_mm')} | {gain} | {folds} |")


def table2(result: dict) -> str:
    """A Markdown table laid out like the paper's Table 2 (all examples, single + multi), with
    the no-learning references on the same test examples in italics below each test set's
    variants, each variant's gain over the best of them, and mean L_d per fold."""
    lines = ["| Model/Train set | Test set | Force MSE [N^2] | Force Absolute Error [N] | "
             "Mean L_d [mm] | Max L_d [mm] | gain over best reference (L_d / force) | folds |",
             "|---|---|---|---|---|---|---|---|"]
    shown = set()
    for row in result["overall"]:
        g = row["gain"]
        lines.append(_row(shown_name(row, result["overall"]), row["test_set"],
                          row["metrics"]["all"],
                          f"{_pct(g['ld_gain'])} / {_pct(g['force_gain'])}", str(row["folds"])))
        key = (row["test_set"], tuple(row["fold_ids"]))
        if key in shown:
            continue
        shown.add(key)
        for name in NAMES:
            lines.append(_row(f"*reference: {name}*", row["test_set"], row["references"][name],
                              "", str(row["folds"])))
    return ("\n".join(lines) + "\n" + _fold_table(result) + coverage_table(result, shown_name)
            + _lump_table(result))


def _lump_table(result: dict) -> str:
    """Over the lump and away from it, per variant: the model's mean L_d and force error
    beside the best reference's on the same examples, and its 90 % coverage (empty without
    a lump)."""
    rows = [r for r in result["overall"] if r.get("lump") is not None]
    if not rows:
        return ""
    lump = rows[0]["lump"]
    x, y = lump["centre_mm"]
    lines = [f"\nOver the lump at ({x:.0f}, {y:.0f}) mm, radius {lump['radius_mm']:.0f} mm (test "
             f"presses within its radius + {lump['reach_mm']:.0f} mm) and away from it:\n",
             "| Model/Train set | Test set | part | examples | Mean L_d [mm] | best reference "
             "L_d [mm] | Force Absolute Error [N] | best reference force [N] | points in 90 % |",
             "|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        for part in PARTS:
            got = row["lump"][part]
            if got is None:
                lines.append(f"| {shown_name(row, result['overall'])} | {row['test_set']} | "
                             f"{part} | 0 | | | | | |")
                continue
            m, g = got["metrics"], got["gain"]
            inside = next((lv["coverage"] for lv in (got["intervals"] or {}).get("levels", [])
                           if abs(lv["level"] - 0.9) < 1e-9), None)
            lines.append(f"| {shown_name(row, result['overall'])} | {row['test_set']} | {part} "
                         f"| {m['n']} | {_num(m['ld_mean_mm'])} | {g['ld_reference']}: "
                         f"{_num(g['ld_reference_mm'])} | {_num(m['force_abs_n'])} | "
                         f"{g['force_reference']}: {_num(g['force_reference_n'])} | "
                         f"{'' if inside is None else f'{inside:.0%}'} |")
    return "\n".join(lines) + "\n"


def footprint_errors(run: LoadedRun, lump: Lump | None = None
                     ) -> tuple[np.ndarray, np.ndarray, Lump | None]:
    """A run's test presses on the footprint: each place's (x, y) (K, 2) m (the mean of its
    examples' tips at their start) and mean L_d (K,) m over its examples (a place: the states'
    location id), and the lump if any: for the recording."""
    errs = example_errors(run)[0]
    pairs = example_pairs(run.states, run.test)
    xy = press_xy(run.states, pairs)
    key = run.states.location[pairs[:, 0].cpu().numpy()] if run.states.location is not None \
        else np.round(xy / PLACE_M).astype(np.int64)
    places, which = np.unique(key, axis=0, return_inverse=True)
    which = which.ravel()
    ld = np.bincount(which, errs.ld_mean) / np.bincount(which)
    centre = np.stack([np.bincount(which, xy[:, k]) / np.bincount(which) for k in (0, 1)], 1)
    return centre, ld, lump


def _fold_table(result: dict) -> str:
    """Per test set, the mean L_d per fold of every variant tested on more than one of its
    folds, beside the references of that fold (empty when no variant has several folds).
    Runs on files that each call their one fold 0 (one MSM set per lab fold) are left out."""
    multi = [r for r in result["overall"] if len(set(r["fold_ids"])) > 1]
    tables = [_one_fold_table(result["runs"], ts, [r for r in multi if r["test_set"] == ts],
                              result["overall"])
              for ts in dict.fromkeys(r["test_set"] for r in multi)]
    return "".join(tables)


def _one_fold_table(runs: list[dict], test_set: str, columns: list[dict],
                    overall: list[dict]) -> str:
    """The per-fold table on ``test_set`` of the variants of the overall rows ``columns``."""
    by_fold: dict[int, dict] = {}
    shown = [c["variant"] for c in columns]
    for run in runs:
        if run["test_set"] == test_set and run["variant"] in shown:
            by_fold.setdefault(run["fold"], {"refs": run["references"], "runs": []})
            by_fold[run["fold"]]["runs"].append(run)
    head = ["fold", *(shown_name(c, overall) for c in columns),
            *(f"*{n}*" for n in DISPLACEMENT)]
    lines = ["", f"Mean L_d per fold on {test_set} [mm] (in brackets: gain over the best "
                 "reference)", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for fold in sorted(by_fold):
        cells = [str(fold)]
        for column in columns:
            run = next((r for r in reversed(by_fold[fold]["runs"])
                        if r["variant"] == column["variant"]), None)
            cells.append("–" if run is None else f"{_num(run['metrics']['all']['ld_mean_mm'])} "
                                                 f"({_pct(run['gain']['ld_gain'])})")
        refs = by_fold[fold]["refs"]
        cells += [f"{refs[n]['ld_mean_mm']:.3f}" for n in DISPLACEMENT]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"

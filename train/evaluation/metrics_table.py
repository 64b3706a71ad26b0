"""The scores as ``metrics.md``: Table 2 laid out like the paper's, the references in italics
below each test set's variants, mean L_d per fold, the intervals' coverage
(:mod:`train.evaluation.coverage_table`) and, with a lump, the rows over it and away from it;
and the lines ``pipeline eval`` prints for a variant that does not beat the references."""

from __future__ import annotations

from data_schema.metrics_doc import Metrics, PooledRow, Row, RunRow, Scores, beats
from train.evaluation.coverage import SHOWN
from train.evaluation.coverage_table import coverage_table
from train.evaluation.references import DISPLACEMENT, NAMES
from train.training.variant import Variant


def shown_name(row: Row, rows: list[PooledRow] | list[RunRow]) -> str:
    """A run's or variant's name as shown: its label, or its full name where another variant
    among ``rows`` has the same label."""
    if any(r.label == row.label and r.variant != row.variant for r in rows):
        return Variant.from_dict(row.variant).full_name
    return row.label


def not_beating(scores: Scores) -> list[str]:
    """One line per variant whose pooled mean L_d or force error does not beat the best
    reference (what ``pipeline eval --strict`` fails on)."""
    lines = []
    for row in scores.overall:
        g = row.gain
        for what, gain, ref in (("mean L_d", g.ld_gain, g.ld_reference),
                                ("force error", g.force_gain, g.force_reference)):
            if not beats(gain):
                worse = "not finite" if gain is None else f"{-gain:.0%} worse"
                lines.append(f"{shown_name(row, scores.overall)} on {row.test_set}: "
                             f"{what} does not beat '{ref}' ({worse})")
    return lines


def table2(scores: Scores) -> str:
    """A Markdown table laid out like the paper's Table 2 (all examples, single + multi), with
    the no-learning references on the same test examples in italics below each test set's
    variants, each variant's gain over the best of them, and mean L_d per fold."""
    lines = ["| Model/Train set | Test set | Force MSE [N^2] | Force Absolute Error [N] | "
             "Mean L_d [mm] | Max L_d [mm] | gain over best reference (L_d / force) | folds |",
             "|---|---|---|---|---|---|---|---|"]
    shown = set()
    for row in scores.overall:
        g = row.gain
        lines.append(_row(shown_name(row, scores.overall), row.test_set, row.metrics.all,
                          f"{_pct(g.ld_gain)} / {_pct(g.force_gain)}", str(row.folds)))
        key = (row.test_set, tuple(row.fold_ids))
        if key in shown:
            continue
        shown.add(key)
        for name in NAMES:
            lines.append(_row(f"*reference: {name}*", row.test_set, row.references[name],
                              "", str(row.folds)))
    return ("\n".join(lines) + "\n" + _fold_table(scores) + coverage_table(scores, shown_name)
            + _lump_table(scores))


def _pct(gain: float | None) -> str:
    return "–" if gain is None else f"{gain:+.0%}"


def _num(value: float | None) -> str:
    return "–" if value is None else f"{value:.3f}"


def _cell(mean: float | None, sd: float | None) -> str:
    """'mean ± sd' to 2 decimals, or '–' where the predictor has no such value."""
    return "–" if mean is None else f"{mean:.2f} ± {sd:.2f}"


def _row(name: str, test_set: str, m: Metrics, gain: str, folds: str) -> str:
    return (f"| {name} | {test_set} | {m.force_mse_n2:.3g} | "
            f"{_cell(m.force_abs_n, m.force_abs_sd_n)} | "
            f"{_cell(m.ld_mean_mm, m.ld_mean_sd_mm)} | "
            f"{_cell(m.ld_max_mm, m.ld_max_sd_mm)} | {gain} | {folds} |")


def _lump_table(scores: Scores) -> str:
    """Over the lump and away from it, per variant: the model's mean L_d and force error
    beside the best reference's on the same examples, and its 90 % coverage (empty without
    a lump)."""
    rows = [(r, r.lump) for r in scores.overall if r.lump is not None]
    if not rows:
        return ""
    lump = rows[0][1]
    x, y = lump.centre_mm
    lines = [f"\nOver the lump at ({x:.0f}, {y:.0f}) mm, radius {lump.radius_mm:.0f} mm (test "
             f"presses within its radius + {lump.reach_mm:.0f} mm) and away from it:\n",
             "| Model/Train set | Test set | part | examples | Mean L_d [mm] | best reference "
             "L_d [mm] | Force Absolute Error [N] | best reference force [N] | points in 90 % |",
             "|---|---|---|---|---|---|---|---|---|"]
    for row, split in rows:
        name = shown_name(row, scores.overall)
        for part, got in split.parts().items():
            if got is None:
                lines.append(f"| {name} | {row.test_set} | {part} | 0 | | | | | |")
                continue
            m, g = got.metrics, got.gain
            level = None if got.intervals is None else got.intervals.at(SHOWN)
            lines.append(f"| {name} | {row.test_set} | {part} "
                         f"| {m.n} | {_num(m.ld_mean_mm)} | {g.ld_reference}: "
                         f"{_num(g.ld_reference_mm)} | {_num(m.force_abs_n)} | "
                         f"{g.force_reference}: {_num(g.force_reference_n)} | "
                         f"{'' if level is None else f'{level.coverage:.0%}'} |")
    return "\n".join(lines) + "\n"


def _fold_table(scores: Scores) -> str:
    """Per test set, the mean L_d per fold of every variant tested on more than one of its
    folds, beside the references of that fold (empty when no variant has several folds).
    Runs on files that each call their one fold 0 (one MSM set per lab fold) are left out."""
    multi = [r for r in scores.overall if len(set(r.fold_ids)) > 1]
    tables = [_one_fold_table(scores.runs, ts, [r for r in multi if r.test_set == ts],
                              scores.overall)
              for ts in dict.fromkeys(r.test_set for r in multi)]
    return "".join(tables)


def _one_fold_table(runs: list[RunRow], test_set: str, columns: list[PooledRow],
                    overall: list[PooledRow]) -> str:
    """The per-fold table on ``test_set`` of the variants of the overall rows ``columns``."""
    refs: dict[int, dict[str, Metrics]] = {}       # each fold's references (its first run's)
    fold_runs: dict[int, list[RunRow]] = {}
    shown = [c.variant for c in columns]
    for run in runs:
        if run.test_set == test_set and run.variant in shown:
            refs.setdefault(run.fold, run.references)
            fold_runs.setdefault(run.fold, []).append(run)
    head = ["fold", *(shown_name(c, overall) for c in columns),
            *(f"*{n}*" for n in DISPLACEMENT)]
    lines = ["", f"Mean L_d per fold on {test_set} [mm] (in brackets: gain over the best "
                 "reference)", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for fold in sorted(fold_runs):
        cells = [str(fold)]
        for column in columns:
            last = next((r for r in reversed(fold_runs[fold]) if r.variant == column.variant),
                        None)
            cells.append("–" if last is None else f"{_num(last.metrics.all.ld_mean_mm)} "
                                                  f"({_pct(last.gain.ld_gain)})")
        cells += [f"{refs[fold][n].ld_mean_mm:.3f}" for n in DISPLACEMENT]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"

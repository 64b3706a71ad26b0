"""The data-scarcity study (paper, "Data Scarcity"): train on 1..n training groups of a fold,
with and without transfer learning, and evaluate each on the fold's test examples.

For a run, the curve retrains its fold with the nested subsets of the manifest
(``train_subsets``), once from scratch and, when the run was fine-tuned from a pre-trained model
(``--init``), once from that model too; beside them, at each subset, the no-learning references
fitted on the same training groups (:mod:`train.evaluation.references`). Written as
``scarcity.json``, ``scarcity.csv`` and a three-panel ``scarcity.png`` (mean L_d, max L_d, force
error over training groups; the references dashed). A model's row also says how many of the
test points and examples fall inside its 90 % intervals (calibrated on the fold's validation
presses at the end of its training), and with one training press the range each share falls in
by chance (:mod:`train.evaluation.coverage_band`): whether they hold with the fewest presses.
"""

from __future__ import annotations

import csv
import dataclasses
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from core.progress import say
from data_schema.metrics_doc import (
    FORCE_LINEAR,
    NEAREST_PRESS,
    NOTHING_MOVES,
    ScarcityRow,
    ScarcityShares,
)
from train.evaluation.coverage import SHOWN
from train.evaluation.coverage_band import band, counts_of
from train.evaluation.run_coverage import coverage_and_band, fold_coverage
from train.evaluation.run_errors import (
    ExampleErrors,
    LoadedRun,
    example_errors,
    load_run,
    reference_errors,
)
from train.evaluation.scoring import metrics
from train.intervals.levels import REPORTED
from train.model.config import CGNNConfig
from train.training.checkpoint import load_checkpoint
from train.training.train_params import TrainInputs, TrainOptions, TrainParams
from train.training.train_stage import run_train

FIELDS = ScarcityRow.keys()      # the CSV's columns: a row's keys, its model's shares last
MODELS = {False: "no TL", True: "TL"}


@dataclasses.dataclass(frozen=True)
class Retraining:
    """A run's fold, to be trained again on its first n training groups with the run's own
    options and network (``epochs`` of them, unless given otherwise)."""

    opts: TrainOptions
    config: CGNNConfig
    data: Path
    splits: Path
    init: Path | None            # the run's --init (its pre-trained model), or None

    @classmethod
    def of(cls, run_dir: Path, epochs: int | None = None) -> Retraining:
        """The retraining of ``run_dir`` (its best.pt's record), at ``epochs`` if given."""
        meta = load_checkpoint(run_dir / "best.pt")["meta"]
        opts = TrainOptions.from_dict(meta["options"])
        return cls(dataclasses.replace(opts, epochs=epochs or opts.epochs),
                   CGNNConfig.from_dict(meta["config"]), Path(meta["data"]["file"]),
                   Path(meta["splits"]), Path(meta["init"]) if meta["init"] else None)

    def groups(self) -> int:
        """How many nested subsets of training groups the fold's manifest gives."""
        return len(json.loads(self.splits.read_text())["folds"][self.opts.fold]["train_subsets"])

    def train(self, n: int, init: Path | None, out: Path, device: str = "cpu") -> LoadedRun:
        """The fold trained on its first ``n`` groups from ``init`` (None: from scratch) into
        ``out``; the run loaded."""
        run_train(TrainInputs(self.data, self.splits, init), out,
                  TrainParams(dataclasses.replace(self.opts, train_groups=n), self.config,
                              device))
        return load_run(out, device)


def scarcity_rows(run_dir: Path, out_dir: Path, epochs: int | None, device: str = "cpu",
                  most: int | None = None) -> list[ScarcityRow]:
    """Retrain ``run_dir``'s fold on 1..n groups (at most ``most``), with and without its
    --init, and score each beside the references fitted on the same groups."""
    again = Retraining.of(run_dir, epochs)
    opts, n_groups = again.opts, again.groups()
    inits = [None] + ([again.init] if again.init else [])
    rows = []
    for n in range(1, min(n_groups, most or n_groups) + 1):
        for init in inits:
            tag = f"fold{opts.fold}_n{n:02d}_{'tl' if init else 'notl'}"
            say(f"scarcity: {tag}")
            run = again.train(n, init, out_dir / tag, device)
            rows.append(_row(opts.fold, n, MODELS[init is not None], example_errors(run)[0],
                             _covered(run, out_dir / tag, with_band=n == 1)))
        rows += [_row(opts.fold, n, name, errs) for name, errs in reference_errors(run).items()]
    return rows


def _row(fold: int, groups: int, predictor: str, errors: ExampleErrors,
         shares: ScarcityShares | None = None) -> ScarcityRow:
    m = metrics(errors).all
    return ScarcityRow(fold=fold, groups=groups, predictor=predictor, ld_mean_mm=m.ld_mean_mm,
                       ld_max_mm=m.ld_max_mm, force_abs_n=m.force_abs_n, shares=shares)


def _covered(run: LoadedRun, run_dir: Path, with_band: bool) -> ScarcityShares:
    """The shares of the fold's test points and examples inside the run's intervals at
    :data:`~train.evaluation.coverage.SHOWN` (None where it keeps none); ``with_band``, also
    the range each falls in by chance (:mod:`train.evaluation.coverage_band`)."""
    c, redrawn = coverage_and_band(run, run_dir) if with_band \
        else (fold_coverage(run, run_dir), None)
    if c is None:
        return ScarcityShares(points_90=None, force_90=None)
    k = REPORTED.index(SHOWN)
    low_high: tuple[float | None, ...]
    if redrawn is None:
        low_high = (None, None, None, None)
    else:
        b = band(counts_of(c), redrawn)
        low_high = (*b["points"][k], *b["force"][k])
    return ScarcityShares(points_90=float(c.inside[k] / c.points[k]),
                          force_90=float(c.force_inside[k] / c.examples[k]),
                          points_90_low=low_high[0], points_90_high=low_high[1],
                          force_90_low=low_high[2], force_90_high=low_high[3])


def curve(rows: list[ScarcityRow], predictor: str,
          value: Callable[[ScarcityRow], float | None]) -> tuple[list[int], list[float]]:
    """Training groups and the mean of ``value`` over folds for one predictor (None
    skipped)."""
    sel = [r for r in rows if r.predictor == predictor and value(r) is not None]
    groups = sorted({r.groups for r in sel})
    return groups, [float(np.mean([value(r) for r in sel if r.groups == g])) for g in groups]


LINES = (("no TL", "tab:red", "o-"), ("TL", "tab:blue", "o-"),
         (NOTHING_MOVES, "tab:gray", "s--"), (NEAREST_PRESS, "tab:green", "^--"),
         (FORCE_LINEAR, "tab:olive", "v--"))


def write_csv(path: Path, rows: list[ScarcityRow]) -> None:
    """The curve as CSV, written to ``path`` (the runner's temporary file)."""
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS)
        w.writeheader()
        w.writerows(r.to_json() for r in rows)


def plot(path: Path, rows: list[ScarcityRow]) -> None:
    """Three panels like the paper's figure: mean L_d, max L_d, force error over groups (log
    scale: a linear fit to one press can be off by newtons), one legend for all; written to
    ``path`` (the runner's temporary file)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    fig, axes = plt.subplots(1, 3, figsize=(12, 4.0))
    panels: tuple[tuple[Callable[[ScarcityRow], float | None], str], ...] = (
        (lambda r: r.ld_mean_mm, "mean $L_d$ [mm]"), (lambda r: r.ld_max_mm, "max $L_d$ [mm]"),
        (lambda r: r.force_abs_n, "force absolute error [N]"))
    for ax, (value, label) in zip(axes, panels, strict=True):
        for name, color, style in LINES:
            groups, mean = curve(rows, name, value)
            if groups:
                ax.plot(groups, mean, style, color=color, label=name)
        ax.set_xlabel("training groups (presses)")
        ax.set_ylabel(label)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.grid(alpha=0.3)
    axes[2].set_yscale("log")
    handles, labels = axes[2].get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", ncol=len(labels), fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.9))
    fig.savefig(path, dpi=120, format="png")
    plt.close(fig)

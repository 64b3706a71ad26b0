"""The data-scarcity study (paper, "Data Scarcity"): train on 1..n training groups of a fold,
with and without transfer learning, and evaluate each on the fold's test examples.

For a run, the curve retrains its fold with the nested subsets of the manifest
(``train_subsets``), once from scratch and, when the run was fine-tuned from a pre-trained model
(``--init``), once from that model too. Written as ``scarcity.json``, ``scarcity.csv`` and a
three-panel ``scarcity.png`` (mean L_d, max L_d, force error over training groups).
"""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path

from core.atomic import atomic_output
from core.progress import say
from train.checkpoint import load_checkpoint
from train.evaluate import metrics, test_errors
from train.loop import TrainOptions, train_run
from train.model import CGNNConfig

FIELDS = ("fold", "groups", "transfer", "ld_mean_mm", "ld_max_mm", "force_abs_n")


def scarcity_rows(run_dir: Path, out_dir: Path, epochs: int | None, device: str = "cpu"
                  ) -> list[dict]:
    """Retrain ``run_dir``'s fold on 1..n groups (with and without its --init); the errors."""
    meta = load_checkpoint(run_dir / "best.pt")["meta"]
    opts = TrainOptions(**meta["options"])
    opts = dataclasses.replace(opts, epochs=epochs or opts.epochs)
    config = CGNNConfig.from_dict(meta["config"])
    data, splits = Path(meta["data"]["file"]), Path(meta["splits"])
    n_groups = len(json.loads(splits.read_text())["folds"][opts.fold]["train_subsets"])
    inits = [None] + ([Path(meta["init"])] if meta["init"] else [])
    rows = []
    for n in range(1, n_groups + 1):
        for init in inits:
            tag = f"fold{opts.fold}_n{n:02d}_{'tl' if init else 'notl'}"
            say(f"scarcity: {tag}")
            sub = dataclasses.replace(opts, train_groups=n)
            train_run(data, splits, out_dir / tag, sub, config, init, device)
            m = metrics(test_errors(out_dir / tag, device)[0])["all"]
            rows.append({"fold": opts.fold, "groups": n, "transfer": init is not None,
                         "ld_mean_mm": m["ld_mean_mm"], "ld_max_mm": m["ld_max_mm"],
                         "force_abs_n": m["force_abs_n"]})
    return rows


def write_csv(path: Path, rows: list[dict]) -> None:
    """The curve as CSV, written atomically."""
    with atomic_output(path) as tmp, open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS)
        w.writeheader()
        w.writerows(rows)


def plot(path: Path, rows: list[dict]) -> None:
    """Three panels like the paper's figure: mean L_d, max L_d, force error over groups."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6))
    panels = (("ld_mean_mm", "mean $L_d$ [mm]"), ("ld_max_mm", "max $L_d$ [mm]"),
              ("force_abs_n", "force absolute error [N]"))
    for ax, (key, label) in zip(axes, panels, strict=True):
        for transfer, name, color in ((False, "Exp no TL", "tab:red"), (True, "Exp TL",
                                                                        "tab:blue")):
            sel = [r for r in rows if r["transfer"] == transfer]
            groups = sorted({r["groups"] for r in sel})
            if not groups:
                continue
            mean = [sum(r[key] for r in sel if r["groups"] == g)
                    / sum(1 for r in sel if r["groups"] == g) for g in groups]
            ax.plot(groups, mean, "o-", color=color, label=name)
        ax.set_xlabel("training groups")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend()
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)

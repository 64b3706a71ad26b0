"""Evaluation on a fold's test split: the paper's Table 2 metrics, per set and overall.

Per example: L_d, the mean over points of the distance between predicted and true deformed
points, and its max over points; the force error |dF_pred - dF|. Per run and set (single,
multi, both): force MSE, force absolute error mean +- sd, mean L_d mean +- sd and max L_d mean
+- sd over examples (mm). Runs of one variant (label) are pooled over their folds, and the
spread of the per-fold means is given beside.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import torch

from core.atomic import atomic_output
from core.errors import BadInput
from data_schema.hdf5 import attr_text
from train.checkpoint import load_checkpoint, model_from
from train.data import SETS, Batch, States, load_manifest, load_states, make_batch, role_examples
from train.loop import Prediction, distances, predict
from train.normalise import Normaliser

SOURCE_NAMES = {"msm": "MSM", "lab": "Exp"}


@dataclass
class ExampleErrors:
    """Per test example of one run."""

    set: np.ndarray          # (E,) "single" | "multi"
    ld_mean: np.ndarray      # (E,) m
    ld_max: np.ndarray       # (E,) m
    force_err: np.ndarray    # (E,) N, predicted - true


def run_label(meta: dict, source: str) -> str:
    """The Table 2 name of a run: model/train set, (TL) when fine-tuned from another run."""
    opts = meta["options"]
    model = "cGNN" if meta["config"]["use_condition"] else "noCond"
    data = SOURCE_NAMES.get(source, source)
    if meta["init"]:
        init = load_checkpoint(meta["init"])["meta"]
        aug = "aug " if init["options"]["point_fraction"] else ""
        with h5py.File(init["data"]["file"], "r") as f:
            first = SOURCE_NAMES.get(attr_text(f.attrs["source"]), "?")
        return f"{model}/{aug}{first} (TL)"
    rot = "rot " if opts.get("rotate") else ""
    return f"{model}/{rot}{'aug ' if opts['point_fraction'] else ''}{data}"


@dataclass
class LoadedRun:
    """A run's best model with the data and test examples of its fold."""

    model: torch.nn.Module
    norm: Normaliser
    states: States
    test: dict[str, np.ndarray]      # set -> example ids
    meta: dict
    splits: Path


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
    return LoadedRun(model, norm, load_states(data).to(device),
                     role_examples(doc, meta["options"]["fold"], "test"), meta, splits)


@torch.no_grad()
def example_errors(run: LoadedRun, transform: Callable[[Batch], Batch] | None = None,
                   predictor: Callable[[Batch], Prediction] | None = None, batch: int = 64
                   ) -> tuple[ExampleErrors, list[tuple[Batch, Prediction]]]:
    """Errors on the test examples, each batch first moved by ``transform`` (a robustness
    test) and predicted by ``predictor`` (another precision; default: the model as it is);
    and a few (batch, prediction) pairs for the recording."""
    predictor = predictor or (lambda b: predict(run.model, run.norm, b))
    cols: dict[str, list] = {"set": [], "ld_mean": [], "ld_max": [], "force_err": []}
    shown: list[tuple[Batch, Prediction]] = []
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


def test_errors(run_dir: Path, device: str = "cpu"
                ) -> tuple[ExampleErrors, dict, list[tuple[Batch, Prediction]]]:
    """Errors of a run's best model on its fold's test examples, its meta, and a few
    (batch, prediction) pairs for the recording."""
    run = load_run(run_dir, device)
    errs, shown = example_errors(run)
    return errs, run.meta, shown


def metrics(e: ExampleErrors) -> dict[str, dict[str, float]]:
    """Table 2 metrics for single, multi and both (mm, N, N^2)."""
    out = {}
    for name, keep in (("single", e.set == "single"), ("multi", e.set == "multi"),
                       ("all", np.ones(len(e.set), bool))):
        if not keep.any():
            continue
        fe = e.force_err[keep]
        out[name] = {"n": int(keep.sum()), "force_mse_n2": float(np.mean(fe**2)),
                     "force_abs_n": float(np.mean(np.abs(fe))),
                     "force_abs_sd_n": float(np.std(np.abs(fe))),
                     "ld_mean_mm": float(np.mean(e.ld_mean[keep]) * 1e3),
                     "ld_mean_sd_mm": float(np.std(e.ld_mean[keep]) * 1e3),
                     "ld_max_mm": float(np.mean(e.ld_max[keep]) * 1e3),
                     "ld_max_sd_mm": float(np.std(e.ld_max[keep]) * 1e3)}
    return out


def pool(errors: list[ExampleErrors]) -> ExampleErrors:
    """All examples of several runs (folds) as one set."""
    return ExampleErrors(*(np.concatenate([getattr(e, k) for e in errors])
                           for k in ("set", "ld_mean", "ld_max", "force_err")))


def evaluate_runs(run_dirs: list[Path], device: str = "cpu") -> dict:
    """Metrics per run and per label (pooled over its folds, with the spread over folds)."""
    runs, by_label = [], {}
    for run in run_dirs:
        errs, meta, _ = test_errors(run, device)
        with h5py.File(meta["data"]["file"], "r") as f:
            source = attr_text(f.attrs["source"])
        label = run_label(meta, source)
        m = metrics(errs)
        runs.append({"run": str(run), "label": label, "fold": meta["options"]["fold"],
                     "test_set": SOURCE_NAMES.get(source, source), "metrics": m})
        by_label.setdefault((label, runs[-1]["test_set"]), []).append((errs, m))
    overall = []
    for (label, test_set), items in by_label.items():
        pooled = metrics(pool([e for e, _ in items]))
        fold_ld = [m["all"]["ld_mean_mm"] for _, m in items]
        overall.append({"label": label, "test_set": test_set, "folds": len(items),
                        "metrics": pooled, "fold_ld_mean_sd_mm": float(np.std(fold_ld))})
    return {"runs": runs, "overall": overall}


def table2(result: dict) -> str:
    """A Markdown table laid out like the paper's Table 2 (all examples, single + multi)."""
    lines = ["| Model/Train set | Test set | Force MSE [N^2] | Force Absolute Error [N] | "
             "Mean L_d [mm] | Max L_d [mm] | folds |",
             "|---|---|---|---|---|---|---|"]
    for row in result["overall"]:
        m = row["metrics"]["all"]
        lines.append(f"| {row['label']} | {row['test_set']} | {m['force_mse_n2']:.3g} | "
                     f"{m['force_abs_n']:.2f} ± {m['force_abs_sd_n']:.2f} | "
                     f"{m['ld_mean_mm']:.2f} ± {m['ld_mean_sd_mm']:.2f} | "
                     f"{m['ld_max_mm']:.2f} ± {m['ld_max_sd_mm']:.2f} | {row['folds']} |")
    return "\n".join(lines) + "\n"


def write_json(path: Path, doc: dict) -> None:
    """Write a JSON document atomically."""
    with atomic_output(path) as tmp:
        Path(tmp).write_text(json.dumps(doc, indent=1))

"""A new lab's day one: the generic model with no lab data, on every lab we have, beside the
predictors that learn nothing, on the same test examples.

    python benchmarks/bench_zero_shot.py [--generic RUN/best.pt] [--labs default 6x6 scattered] \
        [--seeds 0 1 2] [--out DIR]

``--generic``: a checkpoint, or (the default) the generic model shipped with the package.

Each lab is a twin session made as ``pipeline demo`` makes its own (synth -> ingest -> sync ->
extract -> split into 5 folds grouped by press, the lab's options and seed), into
``OUT/<lab>_seed<S>`` (reused when already there). Per fold the generic model predicts the
fold's test examples as they are (zero-shot: no fine-tuning, its own normaliser); "nothing
moves" needs no data and "nearest press" is fitted on the fold's training presses, as in
``pipeline eval``. Printed per lab and seed: each fold's mean L_d (mm) of the model and the two
references, whether the model beats "nothing moves" in every fold, and in which folds it beats
"nearest press"; then a pooled line per lab.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

LABS = {"default": (),
        "6x6": ("--markers", "6x6", "--marker-pitch", "12", "--mocap-rate", "300"),
        "scattered": ("--markers", "scattered:20", "--size", "150x80"),
        "dome": ("--shape", "dome:30")}
FOLDS = 5


def session(out: Path, lab: str, seed: int) -> tuple[Path, Path]:
    """The lab's states and 5-fold manifest (made unless already there)."""
    from pipeline.cli import cli
    from pipeline.demo_plan import PLACES, REPEATS, Lab, session_steps

    folder = out / f"{lab}_seed{seed}"
    states, splits = folder / "session_states.h5", folder / "splits.json"
    if splits.is_file():
        return states, splits
    opts = dict(zip(LABS[lab][::2], LABS[lab][1::2], strict=True))
    spec = Lab(markers=opts.get("--markers", Lab.markers),
               marker_pitch_mm=float(opts.get("--marker-pitch", Lab.marker_pitch_mm)),
               size_mm=opts.get("--size", Lab.size_mm),
               mocap_rate_hz=float(opts.get("--mocap-rate", Lab.mocap_rate_hz)),
               shape=opts.get("--shape", Lab.shape))
    steps = [s.args for s in session_steps(folder, "session", seed, PLACES, REPEATS, spec)]
    steps.append(("split", str(states), "--out", str(splits), "--folds", str(FOLDS),
                  "--seed", str(seed)))
    for args in steps:
        cli.main(["-q", *args, "--no-rrd"], standalone_mode=False)
    return states, splits


def fold_rows(generic: Path, states: Path, splits: Path) -> list[dict[str, float]]:
    """Per fold: the generic model's and the references' mean L_d (mm) on its test examples,
    and their count."""
    from data_schema.metrics_doc import FORCE_LINEAR
    from train.evaluation.run_errors import example_errors, on_lab, reference_errors
    from train.training.checkpoint import load_checkpoint

    state = load_checkpoint(generic, "cpu")
    rows = []
    for fold in range(FOLDS):
        run = on_lab(state, states, splits, fold)
        errs, _ = example_errors(run)
        refs = reference_errors(run)
        rows.append({"n": len(errs.ld_mean), "generic": errs.ld_mean.mean() * 1e3,
                     **{name: e.ld_mean.mean() * 1e3 for name, e in refs.items()
                        if name != FORCE_LINEAR}})
    return rows


def pooled(rows: list[dict[str, float]], key: str) -> float:
    return sum(r[key] * r["n"] for r in rows) / sum(r["n"] for r in rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--generic", default="generic",
                    help="the generic model's checkpoint [default: the one shipped]")
    ap.add_argument("--labs", nargs="+", choices=list(LABS), default=list(LABS))
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--out", type=Path, default=Path("/tmp/bench_zero_shot"))
    a = ap.parse_args()
    import torch

    from data_schema.metrics_doc import NEAREST_PRESS, NOTHING_MOVES
    from train.generic_model import resolve

    torch.set_num_threads(1)
    print("| lab, seed | generic, per fold (mm) | nothing moves | nearest press | beats nothing "
          "moves | beats nearest press |")
    print("|---|---|---|---|---|---|")
    by_lab: dict[str, list[dict[str, float]]] = {}
    for lab in a.labs:
        for seed in a.seeds:
            rows = fold_rows(resolve(a.generic), *session(a.out, lab, seed))
            by_lab.setdefault(lab, []).extend(rows)
            show = {k: " ".join(f"{r[k]:.3f}" for r in rows)
                    for k in ("generic", NOTHING_MOVES, NEAREST_PRESS)}
            still = sum(r["generic"] < r[NOTHING_MOVES] for r in rows)
            near = [k for k, r in enumerate(rows) if r["generic"] < r[NEAREST_PRESS]]
            print(f"| {lab}, {seed} | {show['generic']} | {show[NOTHING_MOVES]} | "
                  f"{show[NEAREST_PRESS]} | {still} of {len(rows)} | folds {near or 'none'} |")
    print("\n| lab | generic, pooled | nothing moves | nearest press |\n|---|---|---|---|")
    for lab, rows in by_lab.items():
        print(f"| {lab} | {pooled(rows, 'generic'):.3f} mm | {pooled(rows, NOTHING_MOVES):.3f} "
              f"mm | {pooled(rows, NEAREST_PRESS):.3f} mm |")


if __name__ == "__main__":
    main()

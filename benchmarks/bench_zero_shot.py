"""A new lab's day one: the generic model with no lab data, on every lab we have, beside the
predictors that learn nothing, on the same test examples.

    python benchmarks/bench_zero_shot.py [--generic RUN/best.pt] [--labs default 6x6 scattered] \
        [--seeds 0 1 2] [--out DIR] [--rings]

``--generic``: a checkpoint, or (the default) the generic model shipped with the package for the
lab: ``generic``, and on a curved lab (``dome``: a 30 mm dome; ``cylinder``: a half-cylinder
50 mm in radius lying on its flat face, an OBJ the twin was not built around) ``generic-curved``.

Each lab is a twin session made as ``pipeline demo`` makes its own (synth -> ingest -> sync ->
extract -> split into 5 folds grouped by press, the lab's options and seed), into
``OUT/<lab>_seed<S>`` (reused when already there). Per fold the generic model predicts the
fold's test examples as they are (zero-shot: no fine-tuning, its own normaliser); "nothing
moves" needs no data and "nearest press" is fitted on the fold's training presses, as in
``pipeline eval``. Printed per lab and seed: each fold's mean L_d (mm) of the model and the two
references, whether the model beats "nothing moves" in every fold, and in which folds it beats
"nearest press"; then a pooled line per lab.

``--rings`` adds, per lab and seed, where the error comes from: over every fold's test
examples, the phantom's points (the tip's aside) in rings of distance from the tip's start
(in x, y), each ring's mean true displacement, the model's predicted displacement and its
error (a ring whose error exceeds its true displacement does worse than "nothing moves"
there), and the tip's own point apart.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

LABS = {"default": (),
        "6x6": ("--markers", "6x6", "--marker-pitch", "12", "--mocap-rate", "300"),
        "scattered": ("--markers", "scattered:20", "--size", "150x80"),
        "dome": ("--shape", "dome:30"),
        "cylinder": ("--shape", "half_cylinder.obj")}   # written into the lab's folder
CURVED = ("dome", "cylinder")
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
    if opts.get("--shape", "").endswith(".obj"):          # a mould the twin was not built for
        from benchmarks.bench_curved import write_half_cylinder

        folder.mkdir(parents=True, exist_ok=True)
        opts["--shape"] = str(write_half_cylinder(folder / opts["--shape"]))
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


RINGS_MM = (0, 10, 20, 40, 1000)


def ring_rows(generic: Path, states: Path, splits: Path) -> list[tuple[str, float, float,
                                                                         float, int]]:
    """Over every fold's test examples: per ring of distance from the tip's start (and the
    tip's own point), the mean true and predicted displacement and error (mm), and the count."""
    import torch

    from train.data import SETS, make_batch
    from train.evaluation.run_errors import on_lab
    from train.model.si_units import predict
    from train.training.checkpoint import load_checkpoint

    state = load_checkpoint(generic, "cpu")
    moved: list[torch.Tensor] = []   # per batch (B, N, 4): distance, true, predicted, error
    masks: list[torch.Tensor] = []
    for fold in range(FOLDS):
        run = on_lab(state, states, splits, fold)
        for name in SETS:
            b = make_batch(run.states, run.states.pairs[name][torch.as_tensor(run.test[name])])
            with torch.no_grad():
                p = predict(run.model, run.norm, b)
            r = (b.points[..., :2] - b.cond[:, None, :2]).norm(dim=2)
            moved.append(torch.stack([r, (b.target - b.points).norm(dim=2),
                                      (p.deformed - b.points).norm(dim=2),
                                      (p.deformed - b.target).norm(dim=2)], -1) * 1e3)
            masks.append(b.mask)
    d, m = torch.cat(moved), torch.cat(masks)
    tip = torch.zeros_like(m)
    tip[:, -1] = True
    rows = []
    for lo, hi in zip(RINGS_MM[:-1], RINGS_MM[1:], strict=True):
        keep = m & ~tip & (d[..., 0] >= lo) & (d[..., 0] < hi)
        rows.append((f"{lo}-{hi} mm" if hi < RINGS_MM[-1] else f"beyond {lo} mm",
                     *(float(d[..., k][keep].mean()) for k in (1, 2, 3)), int(keep.sum())))
    keep = m & tip
    rows.append(("the tip's point", *(float(d[..., k][keep].mean()) for k in (1, 2, 3)),
                 int(keep.sum())))
    return rows


def print_rings(lab: str, seed: int, rows: list[tuple[str, float, float, float, int]]) -> None:
    print(f"\n{lab}, seed {seed}: the generic model's points by distance from the tip\n"
          "| ring | true displacement | predicted | error | points |\n|---|---|---|---|---|")
    for ring, true, pred, err, n in rows:
        print(f"| {ring} | {true:.3f} mm | {pred:.3f} mm | {err:.3f} mm | {n} |")


def pooled(rows: list[dict[str, float]], key: str) -> float:
    return sum(r[key] * r["n"] for r in rows) / sum(r["n"] for r in rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--generic", default=None,
                    help="the generic model's checkpoint [default: the one shipped for the lab: "
                         "generic, or generic-curved on a curved lab]")
    ap.add_argument("--labs", nargs="+", choices=list(LABS), default=list(LABS))
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--out", type=Path, default=Path("/tmp/bench_zero_shot"))
    ap.add_argument("--rings", action="store_true",
                    help="also where the error comes from: rings of distance from the tip")
    a = ap.parse_args()
    import torch

    from data_schema.metrics_doc import NEAREST_PRESS, NOTHING_MOVES
    from train.generic_model import CURVED_NAME, NAME, resolve

    torch.set_num_threads(1)
    print("| lab, seed | generic, per fold (mm) | nothing moves | nearest press | beats nothing "
          "moves | beats nearest press |")
    print("|---|---|---|---|---|---|")
    by_lab: dict[str, list[dict[str, float]]] = {}
    rings = []
    for lab in a.labs:
        for seed in a.seeds:
            files = session(a.out, lab, seed)
            model = resolve(a.generic or (CURVED_NAME if lab in CURVED else NAME))
            rows = fold_rows(model, *files)
            if a.rings:
                rings.append((lab, seed, ring_rows(model, *files)))
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
    for lab, seed, table in rings:
        print_rings(lab, seed, table)


if __name__ == "__main__":
    main()

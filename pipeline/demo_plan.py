"""What ``pipeline demo`` runs: every stage's command line, its inputs and its outputs.

Two settings: ``quick`` (under 10 minutes on 2 CPU cores: a small MSM set, pre-training on 10%
of the points per sample (the paper's aug variant, its best transfer row) for a few epochs,
short fine-tuning) and the paper's (the full MSM set, 250 epochs, batch 32; a GPU is used when
there is one). Both fine-tune on the twin's states over 5 folds with transfer learning, without
it (the baseline) and without it but with rotation augmentation, and evaluate all three.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Step:
    """One command of the demo: ``pipeline ARGS``, reading ``inputs``, writing ``outputs``."""

    args: tuple[str, ...]
    inputs: tuple[Path, ...]
    outputs: tuple[Path, ...]
    clean: tuple[Path, ...] = ()     # removed before a stale step runs again (a run folder)


@dataclass(frozen=True)
class Settings:
    """The knobs that make the demo quick or the paper's."""

    msm_locations: int
    msm_directions: int
    pretrain_epochs: int
    pretrain_point_fraction: float | None
    finetune_epochs: int
    lr: float
    folds: int = 5


# Short runs need a larger step than the paper's 1e-4 to get anywhere in a few epochs.
QUICK = Settings(msm_locations=20, msm_directions=4, pretrain_epochs=12,
                 pretrain_point_fraction=0.1, finetune_epochs=120, lr=1e-3)
PAPER = Settings(msm_locations=100, msm_directions=11, pretrain_epochs=250,
                 pretrain_point_fraction=0.1, finetune_epochs=250, lr=1e-4)
# Only checks the wiring (the test suite runs it): 2 folds, 2 epochs, a tiny MSM set.
SMOKE = Settings(msm_locations=6, msm_directions=2, pretrain_epochs=1,
                 pretrain_point_fraction=0.1, finetune_epochs=2, lr=1e-3, folds=2)


# Fine-tuning variants on the twin's states: transfer learning from the MSM run, the baseline
# without it, and the baseline with rotation augmentation (see benchmarks/speed_accuracy.py).
VARIANTS: tuple[tuple[str, tuple[str, ...]], ...] = (("tl", ()), ("notl", ()),
                                                     ("rot", ("--rotate",)))


def demo_steps(out: Path, seed: int, s: Settings, device: str = "auto") -> list[Step]:
    """The demo's commands in order; each names what it reads and writes (for skipping)."""
    sd = ("--seed", str(seed))
    ses, mcap, synced = out / "session", out / "session.mcap", out / "synced.h5"
    states, splits = out / "states.h5", out / "splits.json"
    msm, msm_splits, pre = out / "msm.h5", out / "msm_splits.json", out / "runs" / "msm"
    steps = [
        Step(("synth", str(ses), *sd, "--locations", "5", "--repeats", "4"), (), (ses,)),
        Step(("ingest", str(ses), "--out", str(mcap)), (ses,), (mcap,)),
        Step(("sync", str(mcap), "--out", str(synced)), (mcap,), (synced,)),
        Step(("extract", str(synced), "--out", str(states), *sd), (synced,), (states,)),
        Step(("split", str(states), "--out", str(splits), "--folds", str(s.folds), *sd),
             (states,), (splits,)),
        Step(("simulate", "--out", str(msm), "--locations", str(s.msm_locations),
              "--directions", str(s.msm_directions), *sd), (), (msm,)),
        Step(("split", str(msm), "--out", str(msm_splits), "--folds", "1", *sd), (msm,),
             (msm_splits,)),
    ]
    aug = ("--point-fraction", str(s.pretrain_point_fraction)) \
        if s.pretrain_point_fraction else ()
    train = ("--device", device, "--lr", str(s.lr), *sd)
    steps.append(Step(("train", "--data", str(msm), "--splits", str(msm_splits), "--out",
                       str(pre), "--epochs", str(s.pretrain_epochs), *aug, *train),
                      (msm, msm_splits), (pre / "best.pt",), (pre,)))
    runs = []
    for fold in range(s.folds):
        for tag, extra in VARIANTS:
            run = out / "runs" / f"exp_{tag}_fold{fold}"
            runs.append(run)
            init = ("--init", str(pre / "best.pt")) if tag == "tl" else ()
            inputs = (states, splits) + ((pre / "best.pt",) if init else ())
            steps.append(Step(("train", "--data", str(states), "--splits", str(splits),
                               "--fold", str(fold), "--out", str(run), "--epochs",
                               str(s.finetune_epochs), *init, *extra, *train), inputs,
                              (run / "best.pt",), (run,)))
    # the recording shows the first run's test examples: a fine-tuned one, not the MSM's
    steps.append(Step(("eval", *map(str, runs), str(pre), "--out", str(out / "metrics.json")),
                      (pre / "best.pt", *(r / "best.pt" for r in runs)),
                      (out / "metrics.json",)))
    return steps

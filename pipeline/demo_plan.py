"""What ``pipeline demo`` runs: every stage's command line, its inputs and its outputs.

The protocol, as a lab would run it:

1. the session: synth -> ingest -> sync -> extract -> split (5 folds of 20 presses);
2. a calibration recording of the same phantom (other presses: 3 places x 2) -> extract ->
   ``fit-msm``: the MSM's constants are fitted to this phantom, on presses that no fold tests;
3. ``simulate --params --layout``: the fitted MSM sampled at the markers' layout, the tip as
   the 26th point, loads inside the markers' footprint: the graph the network is fine-tuned on;
4. pre-training on it, then per fold fine-tuning with transfer learning (``--init``) and the
   same training from scratch (the baseline);
5. eval: Table 2 with the no-learning references, and the data-scarcity study (1..4 training
   presses, with and without transfer learning, beside the references) on a few folds.

Steps marked ``parallel`` do not depend on each other (the fine-tuning runs, the scarcity
runs' folds) and may run side by side (``demo --jobs``).

Settings: ``quick`` (under 5 minutes on 2 CPU cores), the paper's (the full MSM set, 250
epochs, batch 32; a GPU is used when there is one), and ``smoke`` (the wiring only).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from sim.msm import paper


@dataclass(frozen=True)
class Step:
    """One command of the demo: ``pipeline ARGS``, reading ``inputs``, writing ``outputs``."""

    args: tuple[str, ...]
    inputs: tuple[Path, ...]
    outputs: tuple[Path, ...]
    clean: tuple[Path, ...] = ()     # removed before a stale step runs again (a run folder)
    parallel: bool = False           # independent of the parallel steps next to it


@dataclass(frozen=True)
class Settings:
    """The knobs that make the demo quick or the paper's."""

    msm_locations: int
    msm_directions: int
    pretrain_epochs: int
    finetune_epochs: int
    lr: float
    folds: int = 5
    scarcity_folds: int = 2          # folds of the data-scarcity study
    scarcity_groups: int = 4         # training presses 1..this in the study
    batch: int = 32
    fit_sequences: int = 6           # calibration presses fitted


# The recipe the measurements support (README, "Training that learns"): tip offsets, the
# balanced loss, rotation augmentation; the paper's own settings are the flags' defaults.
RECIPE = ("--tip-offsets", "--loss", "balanced", "--rotate", "--ema", "0.99")
# The same without tip offsets: the paper's network, which a predictor pressing one mesh again
# runs far faster (its graph layers do not read the press), for some accuracy (README).
PAPER_NETWORK = tuple(a for a in RECIPE if a != "--tip-offsets")
QUICK = Settings(msm_locations=60, msm_directions=4, pretrain_epochs=40, finetune_epochs=80,
                 lr=2e-3)
PAPER = Settings(msm_locations=paper.LOCATIONS, msm_directions=paper.DIRECTIONS,
                 pretrain_epochs=250, finetune_epochs=250, lr=1e-4, scarcity_folds=5,
                 scarcity_groups=12, fit_sequences=10)
# Only checks the wiring (the test suite runs it): 2 folds, 2 epochs, a tiny MSM set.
SMOKE = Settings(msm_locations=6, msm_directions=2, pretrain_epochs=1, finetune_epochs=2,
                 lr=1e-3, folds=2, scarcity_folds=1, scarcity_groups=1, fit_sequences=2)
CALIBRATION_SEED = 7919          # added to --seed: the calibration presses are other presses

# Fine-tuning variants on the twin's states: transfer learning from the MSM run, and the
# same training from scratch (the baseline).
VARIANTS: tuple[str, ...] = ("tl", "notl")


def session_steps(out: Path, name: str, seed: int, places: int, repeats: int) -> list[Step]:
    """synth -> ingest -> sync -> extract of one twin session: ``out/NAME/`` (the lab files),
    NAME.mcap, NAME_synced.h5 and NAME_states.h5 beside it."""
    sd = ("--seed", str(seed))
    ses, mcap = out / name, out / f"{name}.mcap"
    synced, states = out / f"{name}_synced.h5", out / f"{name}_states.h5"
    return [
        Step(("synth", str(ses), *sd, "--locations", str(places), "--repeats", str(repeats)),
             (), (ses,)),
        Step(("ingest", str(ses), "--out", str(mcap)), (ses,), (mcap,)),
        Step(("sync", str(mcap), "--out", str(synced)), (mcap,), (synced,)),
        Step(("extract", str(synced), "--out", str(states), *sd), (synced,), (states,)),
    ]


def demo_steps(out: Path, seed: int, s: Settings, device: str = "auto",
               recipe: tuple[str, ...] = RECIPE) -> list[Step]:
    """The demo's commands in order; each names what it reads and writes (for skipping).
    ``recipe``: the training flags every run shares (``RECIPE`` or ``PAPER_NETWORK``)."""
    sd = ("--seed", str(seed))
    states, splits = out / "session_states.h5", out / "splits.json"
    calib_states, fit = out / "calibration_states.h5", out / "msm_params.json"
    msm, msm_splits, pre = out / "msm.h5", out / "msm_splits.json", out / "runs" / "msm"
    steps = session_steps(out, "session", seed, 5, 4) + [
        Step(("split", str(states), "--out", str(splits), "--folds", str(s.folds), *sd),
             (states,), (splits,))]
    steps += session_steps(out, "calibration", seed + CALIBRATION_SEED, 3, 2)
    steps += [
        Step(("fit-msm", str(calib_states), "--out", str(fit), "--max-sequences",
              str(s.fit_sequences), *sd), (calib_states,), (fit,)),
        Step(("simulate", "--out", str(msm), "--params", str(fit), "--layout",
              str(calib_states), "--locations", str(s.msm_locations), "--directions",
              str(s.msm_directions), "--max-angle", "20", *sd), (fit, calib_states), (msm,)),
        Step(("split", str(msm), "--out", str(msm_splits), "--folds", "1", *sd), (msm,),
             (msm_splits,)),
    ]
    train = ("--device", device, "--lr", str(s.lr), "--batch", str(s.batch), *recipe, *sd)
    steps.append(Step(("train", "--data", str(msm), "--splits", str(msm_splits), "--out",
                       str(pre), "--epochs", str(s.pretrain_epochs), *train),
                      (msm, msm_splits), (pre / "best.pt",), (pre,)))
    runs = []
    for fold in range(s.folds):
        for tag in VARIANTS:
            run = out / "runs" / f"exp_{tag}_fold{fold}"
            runs.append(run)
            init = ("--init", str(pre / "best.pt")) if tag == "tl" else ()
            inputs = (states, splits) + ((pre / "best.pt",) if init else ())
            steps.append(Step(("train", "--data", str(states), "--splits", str(splits),
                               "--fold", str(fold), "--out", str(run), "--epochs",
                               str(s.finetune_epochs), *init, *train), inputs,
                              (run / "best.pt",), (run,), parallel=True))
    # the recording shows the first run's test examples: a fine-tuned one, not the MSM's
    steps.append(Step(("eval", *map(str, runs), str(pre), "--out", str(out / "metrics.json")),
                      (pre / "best.pt", *(r / "best.pt" for r in runs)),
                      (out / "metrics.json",)))
    for fold in range(s.scarcity_folds):
        run = out / "runs" / f"exp_tl_fold{fold}"
        result = out / "scarcity" / f"fold{fold}.json"
        steps.append(Step(("eval", str(run), "--out", str(result), "--scarcity",
                           "--scarcity-groups", str(s.scarcity_groups), "--no-rrd",
                           "--device", "cuda" if device == "cuda" else "cpu"),
                          (run / "best.pt",), (result,), (result.parent / f"fold{fold}"
                                                          ".scarcity_runs",), parallel=True))
    return steps

"""What ``pipeline demo`` runs: every stage's command line, its inputs and its outputs.

The protocol, as a lab with only its presses would run it:

1. the session: synth -> ingest -> sync -> extract -> split (5 folds of 20 presses); the twin's
   lab knobs (:class:`Lab`: markers, footprint, mocap rate) make it another lab's phantom;
2. per fold, ``fit-msm --splits --fold``: the MSM's constants fitted to this phantom on that
   fold's training presses only (no test press is ever fitted);
3. per fold, ``simulate --params --layout``: that fitted MSM, sized to the lab's footprint,
   sampled at its markers (the tip the last point), loads inside the markers' footprint;
4. per fold, pre-training on it; then fine-tuning with transfer learning (``--init``) from
   that fold's pre-trained model, and the same training from scratch (the baseline);
5. eval: Table 2 with the no-learning references, and the data-scarcity study (1..4 training
   presses, with and without transfer learning, beside the references) on a few folds.

Steps marked ``parallel`` with the same ``batch`` may run side by side (``demo --jobs``), each
as soon as the steps of its batch that write its inputs are done: every fold's fit, MSM,
pre-training and fine-tuning (:data:`FOLDS`), the scarcity runs' folds.

Settings: ``quick`` (minutes on 2 CPU cores), the paper's (the full MSM set, 250 epochs,
batch 32; a GPU is used when there is one), and ``smoke`` (the wiring only).
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
    parallel: bool = False           # independent of the parallel steps of its batch
    batch: str = ""                  # the parallel steps that may run side by side


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
    fit_sequences: int | None = None  # training presses fitted per fold; None: all of them


# The recipe the measurements support (docs/model.md, "Training that learns";
# train/training/recipes.py): the tip's offsets in the heads, the balanced loss, rotation
# augmentation, the weights' average; its step size is the settings' (--lr below overrides the
# recipe's).
RECIPE = ("--recipe", "ours")
# The networks the demo can train, each with the rest of the recipe (docs/results.md compares
# them): the tip's offsets in the heads (the recipe's: graph layers that do not read the
# press, so a mesh pressed again runs the heads alone), in the first layer (every layer reads
# the press), or nowhere (the paper's network: as fast as the first, less accurate).
NETWORKS = {
    "head-offsets": (*RECIPE, "--offsets", "heads"),
    "tip-offsets": (*RECIPE, "--offsets", "graph"),
    "paper": (*RECIPE, "--offsets", "none"),
}
# quick: per fold a small MSM set (16 places x 3 directions) seen for 80 epochs, and the fit on
# 3 training presses: five folds' fits, MSM sets and pre-training cost about twice what the
# former single calibration fit did (measured: docs/results.md, "Learning")
QUICK = Settings(msm_locations=16, msm_directions=3, pretrain_epochs=80, finetune_epochs=80,
                 lr=2e-3, fit_sequences=3)
PAPER = Settings(msm_locations=paper.LOCATIONS, msm_directions=paper.DIRECTIONS,
                 pretrain_epochs=250, finetune_epochs=250, lr=1e-4, scarcity_folds=5,
                 scarcity_groups=12, fit_sequences=10)
# Only checks the wiring (the test suite runs it): 2 folds, 2 epochs, a tiny MSM set.
SMOKE = Settings(msm_locations=6, msm_directions=2, pretrain_epochs=1, finetune_epochs=2,
                 lr=1e-3, folds=2, scarcity_folds=1, scarcity_groups=1, fit_sequences=2)


@dataclass(frozen=True)
class Lab:
    """The twin's lab knobs (``pipeline synth`` options): whose phantom the demo runs on."""

    markers: str = "5x5"             # RxC grid, or scattered:N
    marker_pitch_mm: float = 20.0    # of a grid
    size_mm: str = "100x100"         # the footprint LxW
    mocap_rate_hz: float = 500.0

    def synth_args(self) -> tuple[str, ...]:
        """The synth options that make this lab (none for the default one)."""
        default = Lab()
        pairs = [("--markers", self.markers, default.markers),
                 ("--marker-pitch", f"{self.marker_pitch_mm:g}", f"{default.marker_pitch_mm:g}"),
                 ("--size", self.size_mm, default.size_mm),
                 ("--mocap-rate", f"{self.mocap_rate_hz:g}", f"{default.mocap_rate_hz:g}")]
        return tuple(a for opt, v, d in pairs if v != d for a in (opt, v))

FOLDS = "folds"          # the batch of every per-fold step: run as their inputs are ready
PLACES, REPEATS = 5, 4   # the demo's session: presses at 5 places, 4 at each

# Fine-tuning variants on the twin's states: transfer learning from the MSM run, and the
# same training from scratch (the baseline).
VARIANTS: tuple[str, ...] = ("tl", "notl")


def session_steps(out: Path, name: str, seed: int, places: int, repeats: int,
                  lab: Lab = Lab()) -> list[Step]:
    """synth -> ingest -> sync -> extract of one twin session: ``out/NAME/`` (the lab files),
    NAME.mcap, NAME_synced.h5 and NAME_states.h5 beside it."""
    sd = ("--seed", str(seed))
    ses, mcap = out / name, out / f"{name}.mcap"
    synced, states = out / f"{name}_synced.h5", out / f"{name}_states.h5"
    return [
        Step(("synth", str(ses), *sd, "--locations", str(places), "--repeats", str(repeats),
              *lab.synth_args()), (), (ses,)),
        Step(("ingest", str(ses), "--out", str(mcap)), (ses,), (mcap,)),
        Step(("sync", str(mcap), "--out", str(synced)), (mcap,), (synced,)),
        Step(("extract", str(synced), "--out", str(states), *sd), (synced,), (states,)),
    ]


def msm_dir(out: Path, fold: int) -> Path:
    """Where fold ``fold``'s fitted MSM lives: params.json, msm.h5, splits.json."""
    return out / "msm" / f"fold{fold}"


def pretrain_dir(out: Path, fold: int) -> Path:
    """Fold ``fold``'s pre-training run on its fitted MSM."""
    return out / "runs" / f"msm_fold{fold}"


def demo_steps(out: Path, seed: int, s: Settings, device: str = "auto",
               recipe: tuple[str, ...] = RECIPE, lab: Lab = Lab()) -> list[Step]:
    """The demo's commands in order; each names what it reads and writes (for skipping).
    ``recipe``: the training flags every run shares (``RECIPE``, or one of ``NETWORKS``)."""
    sd = ("--seed", str(seed))
    states, splits = out / "session_states.h5", out / "splits.json"
    steps = session_steps(out, "session", seed, PLACES, REPEATS, lab) + [
        Step(("split", str(states), "--out", str(splits), "--folds", str(s.folds), *sd),
             (states,), (splits,))]
    train = ("--device", device, "--lr", str(s.lr), "--batch", str(s.batch), *recipe, *sd)
    folds = range(s.folds)
    steps += [_fit_step(out, fold, states, splits, s, sd) for fold in folds]
    steps += [_simulate_step(out, fold, states, s, sd) for fold in folds]
    steps += [_msm_split_step(out, fold, sd) for fold in folds]
    steps += [_pretrain_step(out, fold, s, train) for fold in folds]
    runs = []
    for fold in folds:
        for tag in VARIANTS:
            run = out / "runs" / f"exp_{tag}_fold{fold}"
            runs.append(run)
            pre = pretrain_dir(out, fold) / "best.pt"
            init = ("--init", str(pre)) if tag == "tl" else ()
            inputs = (states, splits) + ((pre,) if init else ())
            steps.append(Step(("train", "--data", str(states), "--splits", str(splits),
                               "--fold", str(fold), "--out", str(run), "--epochs",
                               str(s.finetune_epochs), *init, *train), inputs,
                              (run / "best.pt",), (run,), parallel=True, batch=FOLDS))
    # the recording shows the first run's test examples: a fine-tuned one, not the MSM's
    pres = [pretrain_dir(out, fold) for fold in folds]
    steps.append(Step(("eval", *map(str, runs), *map(str, pres), "--out",
                       str(out / "metrics.json")),
                      tuple(r / "best.pt" for r in runs + pres), (out / "metrics.json",)))
    for fold in range(s.scarcity_folds):
        run = out / "runs" / f"exp_tl_fold{fold}"
        result = out / "scarcity" / f"fold{fold}.json"
        steps.append(Step(("eval", str(run), "--out", str(result), "--scarcity",
                           "--scarcity-groups", str(s.scarcity_groups), "--no-rrd",
                           "--device", "cuda" if device == "cuda" else "cpu"),
                          (run / "best.pt",), (result,), (result.parent / f"fold{fold}"
                                                          ".scarcity_runs",),
                          parallel=True, batch="scarcity"))
    return steps


def _fit_step(out: Path, fold: int, states: Path, splits: Path, s: Settings,
              sd: tuple[str, ...]) -> Step:
    """fit-msm on fold ``fold``'s training presses (all of them: at most the session's)."""
    params = msm_dir(out, fold) / "params.json"
    most = s.fit_sequences or PLACES * REPEATS
    return Step(("fit-msm", str(states), "--splits", str(splits), "--fold", str(fold),
                 "--out", str(params), "--max-sequences", str(most), "--workers", "1", *sd),
                (states, splits), (params,), parallel=True, batch=FOLDS)


def _simulate_step(out: Path, fold: int, states: Path, s: Settings,
                   sd: tuple[str, ...]) -> Step:
    """The fold's fitted MSM, sized to the footprint, sampled at the lab's markers."""
    d = msm_dir(out, fold)
    return Step(("simulate", "--out", str(d / "msm.h5"), "--params", str(d / "params.json"),
                 "--layout", str(states), "--locations", str(s.msm_locations), "--directions",
                 str(s.msm_directions), "--max-angle", "20", "--workers", "1", *sd),
                (d / "params.json", states), (d / "msm.h5",), parallel=True, batch=FOLDS)


def _msm_split_step(out: Path, fold: int, sd: tuple[str, ...]) -> Step:
    d = msm_dir(out, fold)
    return Step(("split", str(d / "msm.h5"), "--out", str(d / "splits.json"), "--folds", "1",
                 *sd), (d / "msm.h5",), (d / "splits.json",), parallel=True, batch=FOLDS)


def _pretrain_step(out: Path, fold: int, s: Settings, train: tuple[str, ...]) -> Step:
    d, run = msm_dir(out, fold), pretrain_dir(out, fold)
    return Step(("train", "--data", str(d / "msm.h5"), "--splits", str(d / "splits.json"),
                 "--out", str(run), "--epochs", str(s.pretrain_epochs), *train),
                (d / "msm.h5", d / "splits.json"), (run / "best.pt",), (run,), parallel=True,
                batch=FOLDS)

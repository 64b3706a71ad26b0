"""What ``pipeline demo`` runs: every stage's command line, its inputs and its outputs.

The protocol, as a lab with only its presses would run it:

1. the session: synth -> ingest -> sync -> extract -> split (5 folds of 20 presses); the twin's
   lab knobs (:class:`Lab`: markers, footprint, mocap rate) make it another lab's phantom;
2. the pre-training, one of :class:`Pretraining`:

   - ``shipped`` (the default): none here; every fold starts from the generic model shipped
     with the package (:mod:`train.generic_model`), made by ``generic`` below with its own
     recipe (:mod:`train.training.generic_recipe`, ``scripts/build_generic.py``);
   - ``generic``: that model made here: one model for every lab, pre-trained once on MSM data
     drawn from the prior (``simulate --prior``: springs, footprint, markers and press drawn
     per phantom, :mod:`sim.msm.msm_prior`), with the same seed whatever the lab or the
     demo's seed, so every fold of every lab starts from the same model
     (:func:`generic_steps`; with the quick settings the shipped model's recipe);
   - ``per-fold``: per fold, ``fit-msm --splits --fold`` (the MSM's constants fitted to this
     phantom on that fold's training presses only), ``simulate --params --layout`` (that MSM
     sized to the lab's footprint, sampled at its markers) and a pre-training on it;
   - ``solid``: the shipped model's runs, and beside them per fold the solid model of the
     phantom with its interior (``fit-solid --splits --fold --session``), pressed at the lab's
     markers (``simulate --solid --layout``), the shipped model pre-trained further on it and
     fine-tuned from there (:func:`solid_steps`; runs ``exp_solid_foldK``);
3. per fold, fine-tuning with transfer learning (``--init``) from the pre-trained model, and
   the same training from scratch (the baseline);
4. eval: Table 2 with the no-learning references, and the data-scarcity study (1..4 training
   presses, with and without transfer learning, beside the references) on a few folds.

Steps marked ``parallel`` with the same ``batch`` may run side by side (``demo --jobs``), each
as soon as the steps of its batch that write its inputs are done. Per fold, that batch
(:data:`FOLDS`) holds every fold's fit, MSM, pre-training and fine-tuning, then the scarcity
runs' folds have theirs; with the generic model it holds everything but eval: the session's
stages and the runs from scratch go on while the prior's data are simulated and the generic
model pre-trains (with the shipped one, nothing waits for it).

Settings: ``quick`` (minutes on 2 CPU cores), the paper's (the full MSM set, 250 epochs,
batch 32; a GPU is used when there is one), and ``smoke`` (the wiring only).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import StrEnum
from pathlib import Path

from core.errors import BadInput
from sim.msm import paper
from sim.twin.synth_params import SynthParams
from train import paper as cgnn_paper
from train.generic_model import SHIPPED, SHIPPED_CURVED, resolve
from train.model.config import Offsets
from train.training.generic_recipe import SHIPPED_RECIPE, GenericRecipe


@dataclass(frozen=True)
class Step:
    """One command of the demo: ``pipeline ARGS``, reading ``inputs``, writing ``outputs``."""

    args: tuple[str, ...]
    inputs: tuple[Path, ...]
    outputs: tuple[Path, ...]
    clean: tuple[Path, ...] = ()     # removed before a stale step runs again (a run folder)
    parallel: bool = False           # independent of the parallel steps of its batch
    batch: str = ""                  # the parallel steps that may run side by side
    stage: str = ""                  # the stage its time counts to (default: its command)


PLACES, REPEATS = 5, 4   # the demo's session: presses at 5 places, 4 at each


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
    batch: int = cgnn_paper.BATCH
    fit_sequences: int | None = None  # training presses fitted per fold; None: all of them
    generic: GenericRecipe = SHIPPED_RECIPE   # --pretraining generic: the model made here
    solid_locations: int = 32         # --pretraining solid: places pressed on the fitted solid
    solid_directions: int = 3         # ... directions at each (within 20 degrees)
    solid_epochs: int = 40            # ... the shipped model pre-trained on them
    scarcity_epochs: int | None = None  # the scarcity study's runs (None: finetune_epochs)
    places: int = PLACES              # the twin session's presses: at this many places, ...
    repeats: int = REPEATS            # ... this many at each


# The recipe the measurements support (docs/model.md, "Training that learns";
# train/training/recipes.py), the shipped generic model's (whose network the folds fine-tune):
# the tip's offsets in the heads, the balanced loss, rotation augmentation, the weights'
# average; its step size is the settings' (--lr below overrides the recipe's).
RECIPE = SHIPPED_RECIPE.training_flags()
# The networks the demo can train, each with the rest of the recipe (docs/results.md compares
# them): the tip's offsets in the heads (the recipe's: graph layers that do not read the
# press, so a mesh pressed again runs the heads alone), in the first layer (every layer reads
# the press), or nowhere (the paper's network: as fast as the first, less accurate).
NETWORKS = {
    "head-offsets": (*RECIPE, "--offsets", Offsets.HEADS.value),
    "tip-offsets": (*RECIPE, "--offsets", Offsets.GRAPH.value),
    "paper": (*RECIPE, "--offsets", Offsets.NONE.value),
}
RECIPE_NETWORK = "head-offsets"   # the recipe's own, and so the shipped generic model's
# quick: the generic model made by the shipped model's recipe (the Settings' default,
# train/training/generic_recipe.py); per fold (--pretraining per-fold) a small MSM set (16
# places x 3 directions) seen for 80 epochs, and the fit on 3 training presses (what each
# costs and buys: docs/results.md, "One pre-training for every lab"); each fold fine-tuned
# (TL and scratch alike) 100 epochs, the minutes the single pre-training saved (100 against
# 80: TL 1.5-2 % lower on seeds 0-2, below the per-fold protocol's at 80 on each, 11-13 %
# below scratch at 100; docs/results.md), the scarcity study's runs 80 (its 16 runs a demo
# would cost a fifth more)
QUICK = Settings(msm_locations=16, msm_directions=3, pretrain_epochs=80, finetune_epochs=100,
                 lr=2e-3, fit_sequences=3, scarcity_epochs=80)
PAPER = Settings(msm_locations=paper.LOCATIONS, msm_directions=paper.DIRECTIONS,
                 pretrain_epochs=cgnn_paper.EPOCHS, finetune_epochs=cgnn_paper.EPOCHS,
                 lr=cgnn_paper.LR, scarcity_folds=5,
                 scarcity_groups=12, fit_sequences=10,
                 generic=replace(SHIPPED_RECIPE, phantoms=100, locations=10,
                                 directions=paper.DIRECTIONS, epochs=cgnn_paper.EPOCHS,
                                 lr=cgnn_paper.LR))
# Only checks the wiring (the test suite runs it): 2 folds, 2 epochs, a tiny MSM set, a session
# of 12 presses (4 places, 3 at each: every fold still tests one press at each place).
SMOKE = Settings(msm_locations=6, msm_directions=2, pretrain_epochs=1, finetune_epochs=2,
                 lr=1e-3, folds=2, scarcity_folds=1, scarcity_groups=1, fit_sequences=1,
                 places=4, repeats=3,
                 generic=replace(SHIPPED_RECIPE, phantoms=2, locations=3, directions=1,
                                 epochs=1, lr=1e-3),
                 solid_locations=10, solid_directions=1, solid_epochs=1)


@dataclass(frozen=True)
class Lab:
    """The twin's lab knobs (``pipeline synth`` options, the twin's own by default): whose
    phantom the demo runs on."""

    markers: str = SynthParams.markers                   # RxC grid, or scattered:N
    marker_pitch_mm: float = SynthParams.marker_pitch_mm  # of a grid
    size_mm: str = SynthParams.size                      # the footprint LxW
    mocap_rate_hz: float = SynthParams.rate_hz
    inclusions: tuple[str, ...] = SynthParams.inclusions  # X,Y,DEPTH,RADIUS,RATIO each
    layer: str | None = SynthParams.layer                 # THICKNESS,RATIO
    shape: str | None = SynthParams.shape                 # dome:HEIGHT or a surface file

    def __post_init__(self) -> None:
        """Refuse, in synth's words and before any step runs, what synth would refuse (an
        inclusion outside the block, a layer thicker than it, markers the footprint lacks)."""
        SynthParams(markers=self.markers, marker_pitch_mm=self.marker_pitch_mm,
                    size=self.size_mm, rate_hz=self.mocap_rate_hz,
                    inclusions=tuple(self.inclusions), layer=self.layer, shape=self.shape)

    def synth_args(self) -> tuple[str, ...]:
        """The synth options that make this lab (none for the default one)."""
        default = Lab()
        pairs = [("--markers", self.markers, default.markers),
                 ("--marker-pitch", f"{self.marker_pitch_mm:g}", f"{default.marker_pitch_mm:g}"),
                 ("--size", self.size_mm, default.size_mm),
                 ("--mocap-rate", f"{self.mocap_rate_hz:g}", f"{default.mocap_rate_hz:g}"),
                 ("--layer", self.layer, default.layer), ("--shape", self.shape, default.shape)]
        return tuple(a for opt, v, d in pairs if v is not None and v != d for a in (opt, v)) + \
            tuple(a for inclusion in self.inclusions for a in ("--inclusion", inclusion))

    @property
    def training_flags(self) -> tuple[str, ...]:
        """What this lab's phantom asks of every run trained on it: with an inclusion its
        stiffness, and so the force, depends on where it is pressed, so the force is learnt
        from unturned presses only (``--no-rotate-force``; docs/model.md)."""
        return ("--no-rotate-force",) if self.inclusions else ()

    @property
    def shipped(self) -> Path:
        """The shipped generic model this lab starts from: the one for curved labs on a curved
        phantom."""
        return SHIPPED if self.shape is None else SHIPPED_CURVED


FOLDS = "folds"          # the batch of every per-fold step: run as their inputs are ready
OUT = Path("out/demo")   # where the demo writes unless told

# Fine-tuning variants on the twin's states: transfer learning from the MSM run, and the
# same training from scratch (the baseline).
VARIANTS: tuple[str, ...] = ("tl", "notl")


def session_steps(out: Path, name: str, seed: int, places: int | str, repeats: int,
                  lab: Lab = Lab()) -> list[Step]:
    """synth -> ingest -> sync -> extract of one twin session: ``out/NAME/`` (the lab files),
    NAME.mcap, NAME_synced.h5 and NAME_states.h5 beside it (``places``: a count, or a grid
    ``RxC``, as synth's ``--locations``)."""
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


class Pretraining(StrEnum):
    """How the demo pre-trains (``demo --pretraining``, these words)."""

    SHIPPED = "shipped"      # not at all: every fold starts from the package's generic model
    GENERIC = "generic"      # that model made here, once for every lab
    PER_FOLD = "per-fold"    # per fold, on an MSM fitted to the lab
    SOLID = "solid"          # the shipped model's runs, and beside them per fold on the solid

    @property
    def from_shipped(self) -> bool:
        """Whether the folds fine-tune the shipped generic model (no generic model made
        here): the network is then the shipped model's."""
        return self in (Pretraining.SHIPPED, Pretraining.SOLID)


SOLID_TAG = "solid"                   # the runs fine-tuned from a fold's solid pre-training


def demo_steps(out: Path, seed: int, s: Settings, device: str = "auto",
               recipe: tuple[str, ...] = RECIPE, lab: Lab = Lab(),
               pretraining: Pretraining = Pretraining.SHIPPED) -> list[Step]:
    """The demo's commands in order; each names what it reads and writes (for skipping).
    ``recipe``: the training flags every run shares (``RECIPE``, or one of ``NETWORKS``)."""
    pretraining = Pretraining(pretraining)      # or its word alone ("per-fold")
    if lab.shape is not None and pretraining == Pretraining.PER_FOLD:
        raise BadInput("--pretraining", f"{pretraining} fits an MSM to the lab, a flat "
                       "surface: a curved lab (--shape) pre-trains on its solid "
                       f"({Pretraining.SOLID}), or fine-tunes the shipped generic model "
                       f"({Pretraining.SHIPPED}) or a generic one ({Pretraining.GENERIC})")
    sd = ("--seed", str(seed))
    states, splits = out / "session_states.h5", out / "splits.json"
    session = session_steps(out, "session", seed, s.places, s.repeats, lab) + [
        Step(("split", str(states), "--out", str(splits), "--folds", str(s.folds), *sd),
             (states,), (splits,))]
    train = ("--device", device, "--lr", str(s.lr), "--batch", str(s.batch), *recipe)
    on_lab = (*train, *lab.training_flags)      # the runs on the lab and on its solid
    tags = VARIANTS
    if pretraining.from_shipped:
        inits = [lab.shipped] * s.folds
        steps = [replace(step, parallel=True, batch=FOLDS) for step in session]
        if pretraining == Pretraining.SOLID:
            steps += solid_steps(out, s, states, splits, (*on_lab, *sd), lab.shipped)
            tags = (*VARIANTS, SOLID_TAG)
    elif pretraining == Pretraining.GENERIC:
        pre = generic_steps(out, s.generic, device, recipe)
        inits = [pre[-1].outputs[0]] * s.folds
        steps = pre + [replace(step, parallel=True, batch=FOLDS) for step in session]
    elif pretraining == Pretraining.PER_FOLD:
        pre = per_fold_steps(out, s, states, splits, train, sd)
        inits = [pretrain_dir(out, fold) / "best.pt" for fold in range(s.folds)]
        steps = session + pre
    else:       # a member without a plan (from_shipped's members are hidden from mypy)
        raise AssertionError(f"no plan for --pretraining {pretraining}")
    runs = [(fold, tag, out / "runs" / f"exp_{tag}_fold{fold}") for fold in range(s.folds)
            for tag in tags]
    order = runs if pretraining == Pretraining.PER_FOLD else \
        sorted(runs, key=lambda r: r[1] != "notl")      # scratch first: it waits for nothing
    for fold, tag, run in order:
        start = {"tl": inits[fold], SOLID_TAG: solid_pre_dir(out, fold) / "best.pt"}.get(tag)
        init = ("--init", str(start)) if start is not None else ()
        steps.append(Step(("train", "--data", str(states), "--splits", str(splits),
                           "--fold", str(fold), "--out", str(run), "--epochs",
                           str(s.finetune_epochs), *init, *on_lab, *sd),
                          (states, splits) + ((start,) if start is not None else ()),
                          (run / "best.pt",), (run,), parallel=True, batch=FOLDS,
                          stage="train (fine-tuning)"))
    scarcity = [_scarcity_step(out, fold, s, device) for fold in range(s.scarcity_folds)]
    if pretraining != Pretraining.PER_FOLD:      # the study goes on beside the last runs
        steps += [replace(step, batch=FOLDS) for step in scarcity]
    # the recording shows the first run's test examples: a fine-tuned one, not the MSM's
    finetuned = [run for _, _, run in runs]
    pres = [] if pretraining.from_shipped else \
        list(dict.fromkeys(init.parent for init in inits))      # the pre-trained run(s)
    truth = ("--truth", str(out / "session" / "truth.h5")) if lab.inclusions else ()
    steps.append(Step(("eval", *map(str, finetuned), *map(str, pres), *truth, "--out",
                       str(out / "metrics.json")),
                      tuple(r / "best.pt" for r in finetuned + pres), (out / "metrics.json",)))
    return steps + (scarcity if pretraining == Pretraining.PER_FOLD else [])


def generic_steps(out: Path, g: GenericRecipe, device: str = "auto",
                  recipe: tuple[str, ...] | None = None) -> list[Step]:
    """The generic model made by ``g``: the prior's MSM data (``msm/prior.h5``; with
    ``g.moulds`` the moulds' solids, ``solid/moulds.h5``), one fold of it, and the
    pre-training (``runs/generic``, ``runs/generic_curved``), all with ``g.seed``; the last
    step's output is the model every fold fine-tunes from. ``recipe``: the training flags
    (default: ``g``'s; the demo's another network's)."""
    sd = ("--seed", str(g.seed))
    flags = g.training_flags() if recipe is None else recipe
    init = () if g.start is None else ("--init", g.start)
    train = ("--device", device, "--lr", str(g.lr), "--batch", str(g.batch), *flags, *init)
    if g.moulds:
        prior, splits, run = out / "solid" / "moulds.h5", out / "solid" / "moulds_splits.json", \
            out / "runs" / "generic_curved"
    else:
        prior, splits, run = out / "msm" / "prior.h5", out / "msm" / "prior_splits.json", \
            out / "runs" / "generic"
    moulds = ("--moulds",) if g.moulds else ()
    return [
        Step(("simulate", "--prior", str(g.phantoms), *moulds, "--locations", str(g.locations),
              "--directions", str(g.directions), "--workers", "1", "--out", str(prior), *sd),
             (), (prior,), parallel=True, batch=FOLDS, stage="simulate --prior"),
        Step(("split", str(prior), "--out", str(splits), "--folds", "1", *sd), (prior,),
             (splits,), parallel=True, batch=FOLDS),
        Step(("train", "--data", str(prior), "--splits", str(splits), "--out", str(run),
              "--epochs", str(g.epochs), *train, *sd),
             (prior, splits, *(() if g.start is None else (resolve(g.start),))),
             (run / "best.pt",), (run,), parallel=True, batch=FOLDS,
             stage="train (pre-training)"),
    ]


def per_fold_steps(out: Path, s: Settings, states: Path, splits: Path,
                   train: tuple[str, ...], sd: tuple[str, ...]) -> list[Step]:
    """Per fold: the MSM fitted on its training presses, simulated at the lab's markers, and
    pre-trained on (``runs/msm_foldK``), with the demo's seed ``sd``."""
    folds = range(s.folds)
    return ([_fit_step(out, fold, states, splits, s, sd) for fold in folds]
            + [_simulate_step(out, fold, states, s, sd) for fold in folds]
            + [_msm_split_step(out, fold, sd) for fold in folds]
            + [_pretrain_step(out, fold, s, (*train, *sd)) for fold in folds])


def solid_dir(out: Path, fold: int) -> Path:
    """Where ``--pretraining solid`` keeps a fold's fitted solid and its states."""
    return out / "solid" / f"fold{fold}"


def solid_pre_dir(out: Path, fold: int) -> Path:
    """The shipped model pre-trained further on a fold's solid states."""
    return out / "runs" / f"solid_fold{fold}"


def solid_steps(out: Path, s: Settings, states: Path, splits: Path,
                train: tuple[str, ...], start: Path = SHIPPED) -> list[Step]:
    """Per fold: the solid fitted on its training presses (with the interior the session
    names), pressed at the lab's markers, split, and the shipped model ``start`` (the lab's:
    :attr:`Lab.shipped`) pre-trained on it."""
    steps = []
    for fold in range(s.folds):
        d, run = solid_dir(out, fold), solid_pre_dir(out, fold)
        solid, data, sp = d / "solid.json", d / "states.h5", d / "splits.json"   # each .rrd beside
        steps += [
            Step(("fit-solid", str(states), "--splits", str(splits), "--fold", str(fold),
                  "--session", str(out / "session"), "--out", str(solid)),
                 (states, splits, out / "session" / "session.toml"), (solid,), parallel=True,
                 batch=FOLDS),
            Step(("simulate", "--solid", str(solid), "--layout", str(states), "--locations",
                  str(s.solid_locations), "--directions", str(s.solid_directions),
                  "--max-angle", "20", "--out", str(data)), (solid, states), (data,),
                 parallel=True, batch=FOLDS, stage="simulate --solid"),
            Step(("split", str(data), "--out", str(sp), "--folds", "1"), (data,), (sp,),
                 parallel=True, batch=FOLDS),
            Step(("train", "--data", str(data), "--splits", str(sp), "--out", str(run),
                  "--epochs", str(s.solid_epochs), "--init", str(start), *train),
                 (data, sp, start), (run / "best.pt",), (run,), parallel=True, batch=FOLDS,
                 stage="train (pre-training)")]
    return steps


def _scarcity_step(out: Path, fold: int, s: Settings, device: str) -> Step:
    """The data-scarcity study on fold ``fold``'s TL run: its runs retrained on 1..groups
    training presses, with and without its pre-trained model."""
    run = out / "runs" / f"exp_tl_fold{fold}"
    result = out / "scarcity" / f"fold{fold}.json"
    epochs = ("--scarcity-epochs", str(s.scarcity_epochs)) if s.scarcity_epochs else ()
    return Step(("eval", str(run), "--out", str(result), "--scarcity", "--scarcity-groups",
                 str(s.scarcity_groups), *epochs, "--no-rrd", "--device",
                 "cuda" if device == "cuda" else "cpu"),
                (run / "best.pt",), (result,), (result.parent / f"fold{fold}.scarcity_runs",),
                parallel=True, batch="scarcity")


def _fit_step(out: Path, fold: int, states: Path, splits: Path, s: Settings,
              sd: tuple[str, ...]) -> Step:
    """fit-msm on fold ``fold``'s training presses (all of them: at most the session's)."""
    params = msm_dir(out, fold) / "params.json"
    most = s.fit_sequences or s.places * s.repeats
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
                batch=FOLDS, stage="train (pre-training)")

"""Training the cGNN on one fold: Adam, the paper's loss, validation every epoch, checkpoints.

The loss and the distances are the SI units' (:mod:`train.model.si_units`): ``alpha * L_d +
MSE(dF)``, L_d in metres and the force change in newtons (alpha = 88, the paper's), or "balanced".

Each epoch's shuffle and point sampling (``point_fraction``: the paper's aug variant, that
fraction of the points per sample in training, all in validation and test) come from a
generator seeded by (seed, epoch), so a run killed after epoch e and resumed from ``last.pt``
draws exactly what the uninterrupted run drew: same weights. ``best.pt`` is the epoch with the
lowest validation loss; with ``no_val`` (no validation set, said explicitly) it is the last
epoch. ``rotate`` turns each training example about the surface normal by a random angle
(drawn from the same generator), so the model cannot lean on where on the phantom a press was;
without ``rotate_force`` half of them stay unturned and only those teach the force, which a
lump makes depend on where the phantom is pressed. A non-finite or exploding loss stops the
run naming epoch and batch.

Training that cannot learn says so: the fold's examples are refused where they cannot teach
(:mod:`train.training.fold_data`); a training loss that does not move over the first epochs is
a warning, kept in the checkpoints' meta ("notes") and the recording.

The runner names the files (:class:`~train.training.run_files.RunFiles`) and writes the
checkpoints (``save``: atomically, with their provenance, :mod:`train.training.train_stage`);
:class:`~train.training.run_files.RunWriter` decides when, and appends ``log.csv``. The
defaults of :class:`TrainOptions` are the paper's (:mod:`train.paper`).
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from torch.nn.parallel import DistributedDataParallel

from core.errors import BadInput
from core.progress import say, warn
from data_schema.states import point_names
from train.data import (
    StateTensors,
    make_batch,
)
from train.model.cgnn import CGNN
from train.model.config import CGNNConfig
from train.model.normalise import Normaliser
from train.model.si_units import loss_sum, mean_distance, predict
from train.training.augment import about_normal, move_batch
from train.training.batches import epoch_batches, fixed_batches
from train.training.checkpoint import load_checkpoint
from train.training.distributed import DistContext, from_env
from train.training.fold_data import fit_normaliser, fold_examples
from train.training.run_files import RunFiles, RunWriter, Save
from train.training.train_params import Loss, Schedule, TrainOptions
from train.training.variant import make_variant

EXPLODE = 1e4          # a loss this many times the first epoch's stops the run
# A loss that does not move: the loss of a fixed probe of training examples (all points, no
# augmentation: no sampling noise) changed by less than STALL_REL of itself from before
# training to the end of the first STALL_EPOCHS epochs (or of the run, when shorter). A run
# that learns moves it by percents there.
STALL_EPOCHS = 3
STALL_REL = 1e-4
STALL_PROBE = 64       # training examples in the probe
STILL_SHARE = 0.5      # without rotate_force: the examples left unturned to teach the force


def learning_rate(opts: TrainOptions, epoch: int) -> float:
    """The step size of an epoch: constant, or cosine from ``lr`` to 1 % of it."""
    if opts.schedule is Schedule.CONSTANT or opts.epochs <= 1:
        return opts.lr
    t = epoch / (opts.epochs - 1)
    return opts.lr * (0.01 + 0.99 * 0.5 * (1 + math.cos(math.pi * t)))


def seeded(seed: int, epoch: int) -> torch.Generator:
    """The generator of one epoch's draws (shuffle, points), the same on every resume and
    every device: it draws on the CPU, and the draws are moved to the run's device."""
    return torch.Generator(device="cpu").manual_seed(seed * 1_000_003 + epoch)


def probe_loss(run: Run, opts: TrainOptions) -> float:
    """The loss of the trained weights on the first ``STALL_PROBE`` training examples."""
    return evaluate_pairs(run.model, run.norm, run.states, run.train[:STALL_PROBE], opts.alpha,
                          balanced=balance(run, opts) is not None)["val_loss"]


def stalled(before: float, after: float, epochs: int) -> str | None:
    """A warning when the probe's loss moved by less than ``STALL_REL`` of itself."""
    change = abs(after - before) / max(abs(before), 1e-30)
    if change >= STALL_REL:
        return None
    return (f"the training loss did not move: {before:.7g} -> {after:.7g} on {STALL_PROBE} "
            f"training examples over the first {epochs} epoch(s) (relative change "
            f"{change:.2g} < {STALL_REL:g}); the model is barely learning: raise --lr or "
            "check the data")


def note_warning(run: Run, text: str) -> None:
    """A warning line on stderr (even with --quiet), kept in the checkpoints' meta."""
    warn(text)
    run.meta.setdefault("notes", []).append(f"warning: {text}")


def resolve_device(name: str) -> torch.device:
    """``auto``: CUDA when torch has it, else the CPU."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise BadInput(None, "--device cuda: this torch has no CUDA device")
    return torch.device(name)


@dataclass
class Run:
    """What a training run needs, assembled."""

    model: CGNN
    norm: Normaliser
    optimizer: torch.optim.Optimizer
    states: StateTensors
    train: torch.Tensor        # (E, 2) pairs
    val: torch.Tensor
    start_epoch: int
    best_val: float
    meta: dict
    best_epoch: int = -1
    averaged: CGNN | None = None   # with ``ema``: the average validated and saved as "model"

    @property
    def kept(self) -> CGNN:
        """The weights validated and saved as the run's model."""
        return self.averaged if self.averaged is not None else self.model


def prepare(data: Path, splits: Path, files: RunFiles, opts: TrainOptions,
            config: CGNNConfig, init: Path | None, device: torch.device) -> Run:
    """Load data and fold, build the model (from ``init``'s weights for transfer learning)
    and its optimizer, and resume a killed run from ``files.last``."""
    states, train, val, sha = fold_examples(data, splits, opts)
    init_state = load_checkpoint(init) if init is not None else None
    meta = run_meta(data, splits, init, opts, config, sha, init_state)
    model, norm = initial_model(states, train, opts, config, init, init_state)
    model.to(device)
    averaged = copy.deepcopy(model).requires_grad_(False) if opts.ema is not None else None
    run = Run(model, norm, adam(model.parameters(), opts.lr), states, train, val, 0, math.inf,
              meta, -1, averaged)
    if files.last.is_file():
        resume(run, files.last, device)
    run.states, run.train, run.val = states.to(device), train.to(device), val.to(device)
    return run


def adam(params: Iterable[torch.Tensor], lr: float) -> torch.optim.Adam:
    """The trainer's Adam, fused: one call over all parameters instead of some thirty
    operators each (the same update, rounded differently). A run resumed from a checkpoint of
    an unfused Adam goes on unfused: the optimizer's settings are the checkpoint's, so it
    reaches the weights it would have."""
    return torch.optim.Adam(params, lr=lr, fused=True)


def run_meta(data: Path, splits: Path, init: Path | None, opts: TrainOptions,
             config: CGNNConfig, sha256: str, init_state: dict | None) -> dict:
    """What a run's checkpoints record of it: its options, network, data, manifest, the
    checkpoint it started from, and its variant."""
    return {"options": opts.to_dict(), "config": config.to_dict(),
            "data": {"file": str(Path(data).resolve()), "sha256": sha256,
                     "point_names": point_names(data)},
            "splits": str(Path(splits).resolve()),
            "init": str(Path(init).resolve()) if init else None,
            "variant": make_variant(config, opts, data,
                                    init_state and init_state["meta"]).to_dict()}


def initial_model(states: StateTensors, train: torch.Tensor, opts: TrainOptions,
                  config: CGNNConfig, init: Path | None, init_state: dict | None
                  ) -> tuple[CGNN, Normaliser]:
    """The seeded network and the normaliser of the training examples; with ``init_state``
    (transfer learning) its weights. The normaliser stays this run's own, so a model
    pre-trained on many footprints reads the lab's points centred and scaled as the lab's
    (measured better than the pre-trained model's statistics, most where the lab's footprint
    is far from the prior's mean: docs/results.md, "The lab's own normaliser")."""
    torch.manual_seed(opts.seed)
    model = CGNN(config)
    norm = fit_normaliser(states, train, opts.seed)
    if init_state is None:
        return model, norm
    if CGNNConfig.from_dict(init_state["config"]) != config:
        raise BadInput(init, "its network (widths, k, conditioning or offsets) differs from "
                             "this run's: transfer learning needs the same network")
    model.load_state_dict(init_state["model"])
    return model, norm


def resume(run: Run, last: Path, device: torch.device) -> None:
    """Continue ``run`` from its last checkpoint: weights, average, optimizer, normaliser,
    epoch, best so far and notes; refused when it holds another run."""
    state = load_checkpoint(last, device)
    if _resumable(state["meta"]) != _resumable(run.meta):
        raise BadInput(last, "holds a run with other data, fold, options or network: "
                             "choose another --out or remove it")
    run.model.load_state_dict(state.get("trained", state["model"]))
    if run.averaged is not None:
        run.averaged.load_state_dict(state["model"])
    run.optimizer.load_state_dict(state["optimizer"])
    run.norm = Normaliser.from_dict(state["norm"])
    run.start_epoch, run.best_val = state["epoch"] + 1, state["best_val"]
    run.meta["notes"] = list(state["meta"].get("notes", []))
    run.best_epoch = int(state.get("best_epoch", state["epoch"]))


@torch.no_grad()
def update_average(run: Run, decay: float) -> None:
    """One step of the exponential average: avg <- decay avg + (1 - decay) weights, over all
    parameters in one call."""
    if run.averaged is None:
        raise ValueError("no averaged weights to update: the run keeps no average (ema)")
    torch._foreach_lerp_(list(run.averaged.parameters()), list(run.model.parameters()),
                         1.0 - decay)


def balance(run: Run, opts: TrainOptions) -> Normaliser | None:
    """The normaliser that puts the loss terms in their scales (the balanced loss), or None."""
    return run.norm if opts.loss is Loss.BALANCED else None


def turned(count: int, opts: TrainOptions, g: torch.Generator
           ) -> tuple[torch.Tensor | None, torch.Tensor | None]:
    """The batch's turns about the normal (``rotate``; None: none) and each example's weight
    on the force term (None: 1 each). Without ``rotate_force`` a share :data:`STILL_SHARE` of
    the examples stays unturned and only these teach the force, weighted up to keep the
    term's scale: where the stiffness changes across the footprint (a lump), a turned press
    carries the force of one place to another; the dent's shape does not depend on the
    place, so every example still teaches it."""
    if not opts.rotate:
        return None, None
    angles = torch.rand(count, generator=g) * 2 * math.pi
    if opts.rotate_force:
        return about_normal(angles), None
    still = torch.rand(count, generator=g) < STILL_SHARE
    return about_normal(torch.where(still, 0.0, angles)), still.float() / STILL_SHARE


def stopped_early(run: Run, opts: TrainOptions, epoch: int) -> bool:
    """True once ``patience`` epochs have passed without a better validation loss."""
    return opts.patience is not None and run.best_epoch >= 0 \
        and epoch - run.best_epoch > opts.patience


def _resumable(meta: dict) -> dict:
    """What a resumed run must share with the one it continues (more epochs may be asked)."""
    return {**{k: v for k, v in meta.items() if k not in ("variant", "notes")},  # derived
            "options": {k: v for k, v in meta["options"].items() if k != "epochs"}}


def train_epoch(run: Run, net: torch.nn.Module, opts: TrainOptions, epoch: int,
                ctx: DistContext, first_loss: float | None) -> float:
    """One pass over the training examples; the mean loss."""
    device = run.train.device
    g = seeded(opts.seed, epoch)
    n_points = run.states.points.shape[1]
    net.train()
    for group in run.optimizer.param_groups:
        group["lr"] = learning_rate(opts, epoch)
    total = torch.zeros(2, device=device)
    batches = epoch_batches(run.train, run.states.width, n_points, opts.batch, g)
    for b, chosen in enumerate(batches):
        rows = chosen.rows.to(device)
        pairs = run.train[rows]
        width = n_points if chosen.cols is None else len(chosen.cols)
        keep = max(run.model.config.k + 1, math.ceil(opts.point_fraction * width)) \
            if opts.point_fraction else None
        idx = None
        if keep is not None:
            idx = torch.rand(len(rows), width, generator=g).argsort(1)[:, :keep].to(device)
        turns, force_weight = turned(len(rows), opts, g)
        mine = ctx.my_slice(torch.arange(len(rows), device=device))
        batch = make_batch(run.states, pairs[mine], None if idx is None else idx[mine],
                           chosen.cols)
        if turns is not None:
            batch = move_batch(batch, turns[mine.cpu()], torch.tensor(run.norm.centre))
        loss = loss_sum(predict(net, run.norm, batch), batch, opts.alpha, balance(run, opts),
                        None if force_weight is None else force_weight[mine.cpu()].to(device))
        value = float(loss.detach()) / max(len(mine), 1)
        first_loss = first_loss or value
        if not math.isfinite(value) or value > EXPLODE * first_loss:
            raise BadInput(None, f"training diverged at epoch {epoch}, batch {b}: loss "
                                 f"{value:.4g} (try a lower --lr)")
        run.optimizer.zero_grad(set_to_none=True)
        (loss * ctx.world / len(rows)).backward()     # DDP averages: the global batch's mean
        run.optimizer.step()
        if run.averaged is not None and opts.ema is not None:     # both or neither
            update_average(run, opts.ema)
        total += torch.stack([loss.detach(), torch.tensor(float(len(mine)), device=device)])
    total = ctx.total(total)
    return float(total[0] / total[1])


@torch.no_grad()
def evaluate_pairs(model: torch.nn.Module, norm: Normaliser, states: StateTensors,
                   pairs: torch.Tensor, alpha: float, batch: int = 64,
                   balanced: bool = False) -> dict[str, float]:
    """Mean loss, L_d (mm) and force error (N) over ``pairs`` (all points)."""
    model.eval()
    sums = torch.zeros(4, device=pairs.device)
    for chosen in fixed_batches(len(pairs), states.width, pairs, states.points.shape[1],
                                batch):
        rows = chosen.rows.to(pairs.device)
        b = make_batch(states, pairs[rows], cols=chosen.cols)
        p = predict(model, norm, b)
        sums += torch.stack([loss_sum(p, b, alpha, norm if balanced else None),
                             mean_distance(p, b).sum(),
                             (p.dforce - b.dforce).abs().sum(), sums.new_tensor(float(len(rows)))])
    n = max(float(sums[3]), 1.0)
    return {"val_loss": float(sums[0]) / n, "val_ld_mm": float(sums[1]) / n * 1e3,
            "val_force_abs_n": float(sums[2]) / n}


def train_run(data: Path, splits: Path, files: RunFiles, opts: TrainOptions,
              config: CGNNConfig, init: Path | None, device: str, save: Save) -> Path:
    """Train (or resume from ``files.last``) one fold: ``save`` writes the checkpoints
    ``files.best`` and ``files.last``, and each epoch's row is appended to ``files.log``,
    every few seconds and at the end (:class:`RunWriter`; only the main process writes);
    returns ``files.best``."""
    dev = resolve_device(device)
    ctx = from_env(dev)
    run = prepare(data, splits, files, opts, config, init, dev)
    net = DistributedDataParallel(run.model) if ctx.world > 1 else run.model
    if ctx.main:
        for path in {files.best.parent, files.last.parent, files.log.parent}:
            path.mkdir(parents=True, exist_ok=True)
    if opts.no_val:
        _note(run, "no validation (--no-val): best.pt is the last epoch", ctx.main)
    first = None
    probe = probe_loss(run, opts) if run.start_epoch == 0 and ctx.main else None
    probe_at = min(STALL_EPOCHS, opts.epochs) - 1        # the epoch after which it is checked
    writer = RunWriter(files, save) if ctx.main else None
    for epoch in range(run.start_epoch, opts.epochs):
        if _agreed(ctx, stopped_early(run, opts, epoch), run.train.device):
            say(f"stopped after epoch {epoch}: no better validation in {opts.patience} epochs "
                f"(best: epoch {run.best_epoch + 1})")
            break
        tic = time.perf_counter()
        train_loss = train_epoch(run, net, opts, epoch, ctx, first)
        first = first or train_loss
        if probe is not None and epoch == probe_at \
                and (stall := stalled(probe, probe_loss(run, opts), epoch + 1)):
            note_warning(run, stall)
        metrics = _validate(run, opts)
        secs = time.perf_counter() - tic
        row = {"epoch": epoch, "train_loss": train_loss, **metrics, "seconds": secs,
               "samples_per_s": len(run.train) / secs}
        _track_best(run, epoch, row["val_loss"], last=opts.no_val)
        if writer is not None:
            writer.epoch(checkpoint_state(run, epoch), row, best=run.best_epoch == epoch)
            say(_epoch_line(row, opts.epochs, validated=len(run.val) > 0))
    if writer is not None:
        writer.write()
    return files.best


def _validate(run: Run, opts: TrainOptions) -> dict[str, float]:
    """The validation metrics of the kept weights; NaN without validation (``no_val``)."""
    if len(run.val) == 0:
        return {"val_loss": math.nan, "val_ld_mm": math.nan, "val_force_abs_n": math.nan}
    return evaluate_pairs(run.kept, run.norm, run.states, run.val, opts.alpha,
                          balanced=balance(run, opts) is not None)


def _epoch_line(row: dict, epochs: int, validated: bool) -> str:
    """One epoch's progress line."""
    val = (f"val {row['val_loss']:.5f} (L_d {row['val_ld_mm']:.3f} mm, |dF| "
           f"{row['val_force_abs_n']:.3f} N)") if validated else "no validation"
    return (f"epoch {row['epoch'] + 1}/{epochs}: train {row['train_loss']:.5f}, {val}, "
            f"{row['samples_per_s']:.0f} samples/s")


def _note(run: Run, text: str, main: bool) -> None:
    """A choice the run made, said once and kept in the checkpoints' meta ("notes")."""
    if text not in run.meta.get("notes", []):
        run.meta.setdefault("notes", []).append(text)
    if main:
        say(text)


def run_notes(last: Path) -> list[str]:
    """The notes (choices, warnings) kept in a run's last checkpoint (none when absent)."""
    return list(load_checkpoint(last)["meta"].get("notes", [])) if last.is_file() else []


def _agreed(ctx: DistContext, stop: bool, device: torch.device) -> bool:
    """Stop when any process would: every rank takes the same decision, so none waits for
    another that has left (validation losses may differ in the last bits on a GPU)."""
    return bool(ctx.total(torch.tensor([float(stop)], device=device)) > 0)


def _track_best(run: Run, epoch: int, val_loss: float, last: bool = False) -> None:
    """Remember the best validation loss and its epoch (every rank alike); with ``last``
    (no validation), the last epoch is the best."""
    if last:
        run.best_val, run.best_epoch = val_loss, epoch
    elif val_loss < run.best_val or run.best_epoch < 0:
        run.best_val, run.best_epoch = min(run.best_val, val_loss), epoch


def checkpoint_state(run: Run, epoch: int) -> dict[str, Any]:
    """What a checkpoint holds after ``epoch``: the kept weights, the optimizer, where the run
    stands, the network's config and normaliser, the run's meta (and with ``ema`` the stepped
    weights, for resume). Its tensors are the run's own, not copies."""
    state = {"model": run.kept.state_dict(), "optimizer": run.optimizer.state_dict(),
             "epoch": epoch, "best_val": run.best_val, "best_epoch": run.best_epoch,
             "config": run.meta["config"], "norm": run.norm.to_dict(), "meta": run.meta}
    if run.averaged is not None:
        state["trained"] = run.model.state_dict()     # what the optimizer steps, for resume
    return state

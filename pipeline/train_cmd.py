"""``pipeline train``: the click layer over :func:`train.training.train_stage.run_train`."""

from __future__ import annotations

from pathlib import Path

import click
from click.core import ParameterSource

from core.errors import BadInput
from pipeline.options import Checkpoint, OneOf, ranged, seed_option
from train.generic_model import CURVED_NAME, SHIPPED
from train.generic_model import NAME as GENERIC_NAME
from train.model.config import CGNNConfig, Offsets
from train.training.recipes import PAPER, RECIPES, recipe
from train.training.train_params import DEVICES, Loss, Schedule, TrainOptions, TrainParams

EXISTING = click.Path(exists=True, dir_okay=False, path_type=Path)

T, N = TrainOptions, CGNNConfig     # the option defaults are their fields' (the paper's)
B = {**T.BOUNDS, **N.BOUNDS}       # and the options' bounds theirs


@click.command()
@click.option("--recipe", "recipe_name", type=OneOf(RECIPES), default=PAPER.name,
              show_default=True,
              help="Named training settings: paper (the paper's: the defaults below) or ours "
                   f"({' '.join(RECIPES['ours'].flags())}; see docs/model.md, 'Training that "
                   "learns'); options given here override its values.")
@click.option("--data", required=True, type=EXISTING, help="States file (phantom.states 2.x).")
@click.option("--splits", required=True, type=EXISTING,
              help="Fold manifest of that file (phantom.folds 2.0, from `pipeline split`).")
@click.option("--fold", type=ranged(B["fold"]), default=T.fold, show_default=True)
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Run folder: best.pt, last.pt, log.csv, provenance.json, train.rrd.")
@click.option("--init", type=Checkpoint(), default=None,
              help="Start from this checkpoint's weights (transfer learning from an MSM run; "
                   "the normaliser is fitted on this run's data), or "
                   f"'{GENERIC_NAME}': the generic model shipped with the package, pre-trained "
                   "once on MSM data drawn from the prior, with --recipe ours (docs/model.md); "
                   f"'{CURVED_NAME}': that model pre-trained again on curved moulds' solids, "
                   "where a curved lab starts.")
@click.option("--no-cond", is_flag=True, help="The noCond ablation: no condition C.")
@click.option("--point-fraction", type=ranged(B["point_fraction"]), default=T.point_fraction,
              help="The aug variant: this fraction of the points per sample in training.")
@click.option("--rotate/--no-rotate", default=T.rotate,
              help="Rotation augmentation: turn each training example about the surface "
                   "normal by a random angle.")
@click.option("--rotate-force/--no-rotate-force", default=T.rotate_force,
              help="With --rotate: the force learnt from turned examples too [default]. "
                   "--no-rotate-force: half the examples stay unturned and only they teach "
                   "the force, for a phantom whose stiffness changes across its footprint "
                   "(an inclusion): turned, a press over the lump teaches its force "
                   "elsewhere (docs/model.md).")
@click.option("--offsets", type=OneOf(Offsets), default=N.offsets.value, show_default=True,
              help="Where the network reads each point's offsets from the tip's start and end "
                   "(ours, not the paper's): none (the paper's network), graph (the first "
                   "layer; every layer then reads the press) or heads (the graph layers stay "
                   "press-independent, so a mesh pressed again runs the heads alone); "
                   "docs/model.md, 'Training that learns' and 'Latency'.")
@click.option("--offset-width", type=ranged(B["offset_width"]), default=N.offset_width,
              show_default=True,
              help="With --offsets heads: the numbers per point of their encoding.")
@click.option("--loss", type=OneOf(Loss), default=T.loss.value, show_default=True,
              help="paper: alpha x mean distance (m) + force MSE (N^2); balanced: each term "
                   "divided by its training scale, so neither swamps the other.")
@click.option("--schedule", type=OneOf(Schedule), default=T.schedule.value,
              show_default=True,
              help="Learning rate: constant (the paper), or cosine from --lr to 1 % of it.")
@click.option("--patience", type=ranged(B["patience"]), default=T.patience,
              help="Stop after this many epochs without a better validation loss.")
@click.option("--no-ema", is_flag=True,
              help="No average of the weights (where the recipe keeps one): best.pt holds the "
                   "stepped weights.")
@click.option("--ema", type=ranged(B["ema"]), default=T.ema,
              help="Validate and keep an exponential moving average of the weights over the "
                   "steps with this decay (e.g. 0.99); best.pt holds the average.")
@click.option("--no-val", is_flag=True,
              help="Train without a validation set (a fold that has none is refused "
                   "otherwise): best.pt is then the last epoch.")
@click.option("--train-groups", type=ranged(B["train_groups"]), default=T.train_groups,
              help="Train on the manifest's first N training groups only (data scarcity).")
@click.option("--epochs", type=ranged(B["epochs"]), default=T.epochs, show_default=True)
@click.option("--batch", type=ranged(B["batch"]), default=T.batch, show_default=True)
@click.option("--lr", type=ranged(B["lr"]), default=T.lr, show_default=True,
              help="Learning rate; a training loss that does not move over the first 3 "
                   "epochs (below 1e-4 of itself) is warned of.")
@click.option("--alpha", type=ranged(B["alpha"]), default=T.alpha, show_default=True,
              help="Weight of the mean distance (m) against the force MSE (N^2) in the loss.")
@click.option("--k", type=ranged(B["k"]), default=N.k, show_default=True,
              help="Neighbours per point, itself included.")
@click.option("--device", type=OneOf(DEVICES), default=TrainParams.device, show_default=True)
@click.option("--no-rrd/--rrd", "no_rrd", default=False,
              help="Write no RUN_DIR/train.rrd (the loss curves) [default: --rrd].")
@seed_option(T.seed)
@click.pass_context
def train(ctx: click.Context, recipe_name: str, data: Path, splits: Path, out: Path,
          init: Path | None, device: str, no_rrd: bool, **given: object) -> None:
    """Train the cGNN on one fold (resumes a killed run in the same --out).

    Reads --data and --splits (refused unless the manifest was made from exactly this data:
    sha256), and --init. Loss 88 x mean distance (m) + MSE of the force change (N), or each in
    its scale (--loss balanced); Adam; validation every epoch. Writes --out/best.pt (lowest
    validation loss) and last.pt (both atomic, loaded with weights_only, with their
    provenance; with log.csv's rows, every 10 s and at the end: a killed run started again
    resumes after the last epoch written), log.csv (epoch, losses, validation errors,
    samples/s), provenance.json
    (log.csv's) and train.rrd. --recipe names the settings (the paper's by default); options
    given override it. A NaN or exploding loss stops with the epoch and batch named. Refused:
    a fold without validation examples (unless --no-val), training examples in which nothing
    moves (no point by 1 um, the force not by 1 mN). A training loss that does not move over
    the first 3 epochs is warned of (stderr, the checkpoints' meta "notes" and train.rrd).
    Under torchrun it trains data-parallel (gloo on CPU, nccl on GPU).
    """
    from train.training.train_params import TrainInputs, TrainParams
    from train.training.train_stage import run_train

    opts, config = _settings(recipe_name, _given(ctx, given))
    params = TrainParams(opts, config, device, recipe_name)
    rrd = None if no_rrd else out / "train.rrd"
    _hint_curved(data, init)
    run = run_train(TrainInputs(data, splits, init), out, params, rrd)
    best = f"{run.best} (the last epoch: --no-val, no validation)" if opts.no_val \
        else str(run.best)
    warnings = [n for n in run.notes if n.startswith("warning")]
    click.echo(f"{out}: trained fold {opts.fold} for {opts.epochs} epochs; best checkpoint "
               f"{best}" + (f"; recording {rrd}" if rrd else "")
               + (f"; {len(warnings)} warning(s), see above" if warnings else ""))


def _given(ctx: click.Context, options: dict[str, object]) -> dict[str, object]:
    """The training settings given on the command line (not their defaults), by the names of
    :class:`TrainOptions` and :class:`CGNNConfig`."""
    given = {name: value for name, value in options.items()
             if ctx.get_parameter_source(name) is not ParameterSource.DEFAULT}
    if "no_cond" in given:
        given["use_condition"] = not given.pop("no_cond")
    if given.pop("no_ema", False):
        if "ema" in given:
            raise BadInput(None, "--ema and --no-ema: keep an average of the weights or not")
        given["ema"] = None
    return given


def _settings(recipe_name: str, given: dict[str, object]) -> tuple[TrainOptions, CGNNConfig]:
    """The recipe's TrainOptions and CGNNConfig, with the ``given`` settings in place of its
    values; a network the recipe's offsets and ``--no-cond`` cannot make says how to."""
    chosen = recipe(recipe_name)
    try:
        return chosen.settings(**given)
    except BadInput as e:
        if given.get("use_condition") is False and "offsets" in chosen.network \
                and "offsets" not in given:
            raise BadInput(None, f"{e.what} (the {recipe_name} recipe gives --offsets "
                                 f"{chosen.network['offsets']}: add --offsets none)") from None
        raise


def _hint_curved(data: Path, init: Path | None) -> None:
    """On a curved lab's states, a start from the flat generic model is named on stderr with
    the model made for curved phantoms (it starts a curved lab better: docs/stages.md); not on
    simulated ones (the model for curved labs is made so)."""
    from data_schema.states import is_curved, states_source

    if init is not None and init.resolve() == SHIPPED.resolve() and \
            states_source(data) == "lab" and is_curved(data):
        click.echo(f"note: {data} holds a curved phantom's states; --init {CURVED_NAME} starts "
                   "from the generic model for curved phantoms", err=True)

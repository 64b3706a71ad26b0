"""``pipeline train``: the click layer over :func:`train.training.train_stage.run_train`."""

from __future__ import annotations

from pathlib import Path

import click
from click.core import ParameterSource

import train.paper as paper
from core.errors import BadInput
from pipeline.options import bounded_int, finite_float, seed_option
from train.model.config import CGNNConfig, Offsets
from train.training.recipes import RECIPES, recipe
from train.training.train_params import TrainOptions

EXISTING = click.Path(exists=True, dir_okay=False, path_type=Path)
# the options that are no training setting (TrainOptions, CGNNConfig): a recipe sets none
NOT_SETTINGS = ("data", "splits", "out", "init", "device", "rrd", "recipe_name")
NETWORK = CGNNConfig()                 # the paper's network: the defaults of its options


@click.command()
@click.option("--recipe", "recipe_name", type=click.Choice(list(RECIPES)), default="paper",
              show_default=True,
              help="Named training settings: paper (the paper's: the defaults below) or ours "
                   f"({' '.join(RECIPES['ours'].flags())}; see docs/model.md, 'Training that "
                   "learns'); options given here override its values.")
@click.option("--data", required=True, type=EXISTING, help="States file (phantom.states 2.x).")
@click.option("--splits", required=True, type=EXISTING,
              help="Fold manifest of that file (phantom.folds 2.0, from `pipeline split`).")
@click.option("--fold", type=bounded_int(0), default=0, show_default=True)
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Run folder: best.pt, last.pt, log.csv, provenance.json, train.rrd.")
@click.option("--init", type=EXISTING, default=None,
              help="Start from this checkpoint (transfer learning from an MSM run).")
@click.option("--no-cond", is_flag=True, help="The noCond ablation: no condition C.")
@click.option("--point-fraction", type=finite_float(0, 1, min_open=True), default=None,
              help="The aug variant: this fraction of the points per sample in training.")
@click.option("--rotate/--no-rotate", default=False,
              help="Rotation augmentation: turn each training example about the surface "
                   "normal by a random angle.")
@click.option("--offsets", type=click.Choice([o.value for o in Offsets]),
              default=NETWORK.offsets.value, show_default=True,
              help="Where the network reads each point's offsets from the tip's start and end "
                   "(ours, not the paper's): none (the paper's network), graph (the first "
                   "layer; every layer then reads the press) or heads (the graph layers stay "
                   "press-independent, so a mesh pressed again runs the heads alone); "
                   "docs/model.md, 'Training that learns' and 'Latency'.")
@click.option("--offset-width", type=bounded_int(1), default=NETWORK.offset_width,
              show_default=True,
              help="With --offsets heads: the numbers per point of their encoding.")
@click.option("--loss", type=click.Choice(["paper", "balanced"]), default=paper.LOSS,
              show_default=True,
              help="paper: alpha x mean distance (m) + force MSE (N^2); balanced: each term "
                   "divided by its training scale, so neither swamps the other.")
@click.option("--schedule", type=click.Choice(["constant", "cosine"]), default=paper.SCHEDULE,
              show_default=True,
              help="Learning rate: constant (the paper), or cosine from --lr to 1 % of it.")
@click.option("--patience", type=bounded_int(1), default=None,
              help="Stop after this many epochs without a better validation loss.")
@click.option("--no-ema", is_flag=True,
              help="No average of the weights (where the recipe keeps one): best.pt holds the "
                   "stepped weights.")
@click.option("--ema", type=finite_float(0, 1, min_open=True, max_open=True), default=None,
              help="Validate and keep an exponential moving average of the weights over the "
                   "steps with this decay (e.g. 0.99); best.pt holds the average.")
@click.option("--no-val", is_flag=True,
              help="Train without a validation set (a fold that has none is refused "
                   "otherwise): best.pt is then the last epoch.")
@click.option("--train-groups", type=bounded_int(1), default=None,
              help="Train on the manifest's first N training groups only (data scarcity).")
@click.option("--epochs", type=bounded_int(1), default=paper.EPOCHS, show_default=True)
@click.option("--batch", type=bounded_int(1), default=paper.BATCH, show_default=True)
@click.option("--lr", type=finite_float(0, 1, min_open=True, why="Adam's step size: above 1 "
                                                                 "it diverges"),
              default=paper.LR, show_default=True,
              help="Learning rate; a training loss that does not move over the first 3 "
                   "epochs (below 1e-4 of itself) is warned of.")
@click.option("--alpha", type=finite_float(0, 1e4, min_open=True,
                                           why="beyond 1e4 the force term no longer counts"),
              default=paper.ALPHA, show_default=True,
              help="Weight of the mean distance (m) against the force MSE (N^2) in the loss.")
@click.option("--k", type=bounded_int(2), default=paper.K, show_default=True,
              help="Neighbours per point, itself included.")
@click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="auto",
              show_default=True)
@click.option("--rrd/--no-rrd", default=True, show_default=True,
              help="Write RUN_DIR/train.rrd (the loss curves).")
@seed_option
@click.pass_context
def train(ctx: click.Context, recipe_name: str, data: Path, splits: Path, out: Path,
          init: Path | None, device: str, rrd: bool, **given: object) -> None:
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

    opts, config = _settings(ctx, recipe_name)
    if opts.no_val and opts.patience is not None:
        raise BadInput(None, "--patience counts epochs without a better validation loss: "
                             "not with --no-val")
    params = TrainParams(opts, config, device, recipe_name)
    run = run_train(TrainInputs(data, splits, init), out, params,
                    out / "train.rrd" if rrd else None)
    best = f"{run.best} (the last epoch: --no-val, no validation)" if opts.no_val \
        else str(run.best)
    warnings = [n for n in run.notes if n.startswith("warning")]
    click.echo(f"{out}: trained fold {opts.fold} for {opts.epochs} epochs; best checkpoint "
               f"{best}" + (f"; recording {out / 'train.rrd'}" if rrd else "")
               + (f"; {len(warnings)} warning(s), see above" if warnings else ""))


def _settings(ctx: click.Context, recipe_name: str) -> tuple[TrainOptions, CGNNConfig]:
    """The recipe's TrainOptions and CGNNConfig, with the options given on the command line
    (not their defaults) in place of its values."""
    given = {name: value for name, value in ctx.params.items() if name not in NOT_SETTINGS
             and ctx.get_parameter_source(name) is not ParameterSource.DEFAULT}
    if "no_cond" in given:
        given["use_condition"] = not given.pop("no_cond")
    if given.pop("no_ema", False):
        if "ema" in given:
            raise click.UsageError("--ema and --no-ema: keep an average of the weights or not")
        given["ema"] = None
    chosen = recipe(recipe_name)
    try:
        return chosen.settings(**given)
    except ValueError as e:          # the network's own check (CGNNConfig)
        hint = f" (the {recipe_name} recipe gives --offsets {chosen.network['offsets']}: " \
            "add --offsets none)" if "offsets" in chosen.network and "offsets" not in given \
            else ""
        raise click.UsageError(f"{e}{hint}") from None

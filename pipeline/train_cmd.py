"""``pipeline train``: the click layer over :func:`train.train_stage.run_train`."""

from __future__ import annotations

from pathlib import Path

import click

from core.errors import BadInput
from pipeline.options import bounded_int, finite_float, seed_option

EXISTING = click.Path(exists=True, dir_okay=False, path_type=Path)


@click.command()
@click.option("--data", required=True, type=EXISTING, help="States file (phantom.states 2.x).")
@click.option("--splits", required=True, type=EXISTING,
              help="Fold manifest of that file (phantom.folds 2.0, from `pipeline split`).")
@click.option("--fold", type=bounded_int(0), default=0, show_default=True)
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Run folder: best.pt, last.pt, log.csv, train.rrd.")
@click.option("--init", type=EXISTING, default=None,
              help="Start from this checkpoint (transfer learning from an MSM run).")
@click.option("--no-cond", is_flag=True, help="The noCond ablation: no condition C.")
@click.option("--point-fraction", type=finite_float(0, 1, min_open=True), default=None,
              help="The aug variant: this fraction of the points per sample in training.")
@click.option("--rotate", is_flag=True,
              help="Rotation augmentation: turn each training example about the surface "
                   "normal by a random angle.")
@click.option("--tip-offsets", is_flag=True,
              help="Also give the first layer each point's offset from the tip's start and end "
                   "(ours, not the paper's; see README, 'Training that learns').")
@click.option("--loss", type=click.Choice(["paper", "balanced"]), default="paper",
              show_default=True,
              help="paper: alpha x mean distance (m) + force MSE (N^2); balanced: each term "
                   "divided by its training scale, so neither swamps the other.")
@click.option("--schedule", type=click.Choice(["constant", "cosine"]), default="constant",
              show_default=True,
              help="Learning rate: constant (the paper), or cosine from --lr to 1 % of it.")
@click.option("--patience", type=bounded_int(1), default=None,
              help="Stop after this many epochs without a better validation loss.")
@click.option("--ema", type=finite_float(0, 1, min_open=True, max_open=True), default=None,
              help="Validate and keep an exponential moving average of the weights over the "
                   "steps with this decay (e.g. 0.99); best.pt holds the average.")
@click.option("--no-val", is_flag=True,
              help="Train without a validation set (a fold that has none is refused "
                   "otherwise): best.pt is then the last epoch.")
@click.option("--train-groups", type=bounded_int(1), default=None,
              help="Train on the manifest's first N training groups only (data scarcity).")
@click.option("--epochs", type=bounded_int(1), default=250, show_default=True)
@click.option("--batch", type=bounded_int(1), default=32, show_default=True)
@click.option("--lr", type=finite_float(0, 1, min_open=True, why="Adam's step size: above 1 "
                                                                 "it diverges"),
              default=1e-4, show_default=True,
              help="Learning rate; a training loss that does not move over the first 3 "
                   "epochs (below 1e-4 of itself) is warned of.")
@click.option("--alpha", type=finite_float(0, 1e4, min_open=True,
                                           why="beyond 1e4 the force term no longer counts"),
              default=88.0,
              show_default=True,
              help="Weight of the mean distance (m) against the force MSE (N^2) in the loss.")
@click.option("--k", type=bounded_int(2), default=5, show_default=True,
              help="Neighbours per point, itself included.")
@click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default="auto",
              show_default=True)
@click.option("--rrd/--no-rrd", default=True, show_default=True,
              help="Write RUN_DIR/train.rrd (the loss curves).")
@seed_option
def train(data: Path, splits: Path, fold: int, out: Path, init: Path | None, no_cond: bool,
          point_fraction: float | None, rotate: bool, tip_offsets: bool, loss: str,
          schedule: str, patience: int | None, ema: float | None, no_val: bool,
          train_groups: int | None, epochs: int,
          batch: int, lr: float, alpha: float, k: int, device: str, rrd: bool, seed: int) -> None:
    """Train the cGNN on one fold (resumes a killed run in the same --out).

    Reads --data and --splits (refused unless the manifest was made from exactly this data:
    sha256), and --init. Loss 88 x mean distance (m) + MSE of the force change (N), or each in
    its scale (--loss balanced); Adam; validation every epoch. Writes --out/best.pt (lowest
    validation loss) and last.pt (each epoch; both atomic, loaded with weights_only), log.csv
    (epoch, losses, validation errors, samples/s) and train.rrd. A NaN or exploding loss stops
    with the epoch and batch named. Refused: a fold without validation examples (unless
    --no-val), training examples in which nothing moves (no point by 1 um, the force not by
    1 mN). A training loss that does not move over the first 3 epochs is warned of (stderr,
    the checkpoints' meta "notes" and train.rrd). Under torchrun it trains data-parallel
    (gloo on CPU, nccl on GPU).
    """
    from train.loop import TrainOptions
    from train.model import CGNNConfig
    from train.train_stage import run_train

    if tip_offsets and no_cond:
        raise click.UsageError("--tip-offsets are the condition C: not with --no-cond")
    if no_val and patience is not None:
        raise BadInput(None, "--patience counts epochs without a better validation loss: "
                             "not with --no-val")
    opts = TrainOptions(fold=fold, epochs=epochs, batch=batch, lr=lr, alpha=alpha,
                        point_fraction=point_fraction, train_groups=train_groups, seed=seed,
                        rotate=rotate, loss=loss, schedule=schedule, patience=patience, ema=ema,
                        no_val=no_val)
    config = CGNNConfig(k=k, use_condition=not no_cond, tip_offsets=tip_offsets)
    run = run_train(data, splits, out, opts, config, init, device, rrd)
    best = f"{run.best} (the last epoch: --no-val, no validation)" if no_val else str(run.best)
    warnings = [n for n in run.notes if n.startswith("warning")]
    click.echo(f"{out}: trained fold {fold} for {epochs} epochs; best checkpoint {best}"
               + (f"; recording {out / 'train.rrd'}" if rrd else "")
               + (f"; {len(warnings)} warning(s), see above" if warnings else ""))

"""Every setting of ``pipeline train``: what a run learns (:class:`TrainOptions`, the paper's
defaults from :mod:`train.paper`), the network (:class:`train.model.config.CGNNConfig`), the
device and the recipe's name (:class:`TrainParams`), and what it reads (:class:`TrainInputs`).

Plain data without torch: the command line reads its defaults here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import train.paper as paper
from train.model.config import CGNNConfig


@dataclass(frozen=True)
class TrainOptions:
    """Everything that decides what a run learns (a resumed run must match it)."""

    fold: int = 0
    epochs: int = paper.EPOCHS
    batch: int = paper.BATCH
    lr: float = paper.LR
    alpha: float = paper.ALPHA
    point_fraction: float | None = None
    train_groups: int | None = None
    seed: int = 0
    rotate: bool = False
    loss: str = paper.LOSS           # "paper": alpha L_d + MSE; "balanced": each in its scale
    schedule: str = paper.SCHEDULE   # "constant" or "cosine" (to 1 % of lr at the last epoch)
    patience: int | None = None      # stop after this many epochs without a better validation
    ema: float | None = None         # validate and keep an exponential average of the weights
    no_val: bool = False             # train without validation: best.pt is the last epoch


@dataclass(frozen=True)
class TrainInputs:
    """What a run reads: the states file, its fold manifest, and optionally the checkpoint to
    start from (transfer learning)."""

    data: Path
    splits: Path
    init: Path | None = None

    def files(self) -> list[Path]:
        return [self.data, self.splits, *([self.init] if self.init is not None else [])]


@dataclass(frozen=True)
class TrainParams:
    """Every setting of a run: the training options, the network, the device, and the name of
    the recipe they came from (recorded in the provenance; the settings are what count)."""

    options: TrainOptions = field(default_factory=TrainOptions)
    config: CGNNConfig = field(default_factory=CGNNConfig)
    device: str = "auto"
    recipe: str | None = None

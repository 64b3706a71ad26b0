"""Every setting of ``pipeline train``: what a run learns (:class:`TrainOptions`, the paper's
defaults from :mod:`train.paper`), the network (:class:`train.model.config.CGNNConfig`), the
device and the recipe's name (:class:`TrainParams`), and what it reads (:class:`TrainInputs`).

The settings the code branches on are enums (:class:`Loss`, :class:`Schedule`), from the command
line to the loop; a checkpoint keeps their values as plain text (:meth:`TrainOptions.to_dict`).
Each setting's bounds are stated here (``BOUNDS``) and checked as the settings are made. Plain
data without torch: the command line reads its defaults, choices and bounds here.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from enum import StrEnum
from pathlib import Path
from types import MappingProxyType
from typing import Any, ClassVar

import train.paper as paper
from core.bounds import Bound, check_bounds, one_of
from core.errors import BadInput
from train.model.config import CGNNConfig

DEVICES = ("auto", "cpu", "cuda")     # where a run trains (auto: CUDA when torch has it)


class Loss(StrEnum):
    """The training loss (:func:`train.model.si_units.loss_sum`)."""

    PAPER = "paper"          # alpha L_d + MSE of the force change (the paper's)
    BALANCED = "balanced"    # each term divided by its training scale


class Schedule(StrEnum):
    """The learning rate over the epochs (:func:`train.training.loop.learning_rate`)."""

    CONSTANT = "constant"    # the paper's
    COSINE = "cosine"        # from lr to 1 % of it at the last epoch


@dataclass(frozen=True)
class TrainOptions:
    """Everything that decides what a run learns (a resumed run must match it); bad input, in
    one line naming the setting, where one is out of its bounds."""

    fold: int = 0
    epochs: int = paper.EPOCHS
    batch: int = paper.BATCH
    lr: float = paper.LR
    alpha: float = paper.ALPHA
    point_fraction: float | None = None
    train_groups: int | None = None
    seed: int = 0
    rotate: bool = False
    rotate_force: bool = True        # with rotate: the force learnt from turned examples too
    loss: Loss = Loss.PAPER
    schedule: Schedule = Schedule.CONSTANT
    patience: int | None = None      # stop after this many epochs without a better validation
    ema: float | None = None         # validate and keep an exponential average of the weights
    no_val: bool = False             # train without validation: best.pt is the last epoch

    BOUNDS: ClassVar[Mapping[str, Bound]] = MappingProxyType({
        "fold": Bound(0, whole=True),
        "epochs": Bound(1, whole=True),
        "batch": Bound(1, whole=True),
        "lr": Bound(0, 1, min_open=True, why="Adam's step size: above 1 it diverges"),
        "alpha": Bound(0, 1e4, min_open=True, why="beyond 1e4 the force term no longer counts"),
        "point_fraction": Bound(0, 1, min_open=True),
        "train_groups": Bound(1, whole=True),
        "patience": Bound(1, whole=True),
        "ema": Bound(0, 1, min_open=True, max_open=True),
    })

    def __post_init__(self) -> None:
        """The one check of the options; a loss or schedule given by its value (a checkpoint's
        text) becomes its member."""
        object.__setattr__(self, "loss", one_of(Loss, self.loss, "loss"))
        object.__setattr__(self, "schedule", one_of(Schedule, self.schedule, "schedule"))
        check_bounds(self, self.BOUNDS)
        if self.no_val and self.patience is not None:
            raise BadInput(None, "patience counts epochs without a better validation loss: "
                                 "not with no_val")
        if not (self.rotate or self.rotate_force):
            raise BadInput(None, "--no-rotate-force leaves the force's examples unturned by "
                                 "the rotation: it needs --rotate (with --recipe ours)")

    def to_dict(self) -> dict[str, Any]:
        """Plain types, for a checkpoint loaded with ``weights_only``."""
        return {**asdict(self), "loss": self.loss.value, "schedule": self.schedule.value}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TrainOptions:
        """From :meth:`to_dict`'s form (an older form: :mod:`train.training.migrate` first)."""
        return cls(**d)


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
    device: str = DEVICES[0]
    recipe: str | None = None

    def __post_init__(self) -> None:
        if self.device not in DEVICES:
            raise BadInput(None, f"device {self.device!r}: must be one of {', '.join(DEVICES)}")

"""Named training recipes: each a set of training settings given by one name.

- ``paper``: the paper's settings (:mod:`train.paper`), the dataclasses' defaults; what plain
  ``pipeline train`` runs.
- ``ours``: the recipe the measurements support (docs/model.md, "Training that learns"): the
  tip's offsets in the heads (graph layers that do not read the press: a mesh pressed again
  runs the heads alone), the balanced loss, rotation augmentation, an exponential average of
  the weights (decay 0.99) and a step size of 2e-3; the paper's otherwise. Each part can be
  switched off on the command line (``--offsets none --loss paper --no-rotate --no-ema``).

A recipe names only what it changes; settings given explicitly (``pipeline train --lr ...``,
or keyword arguments of :meth:`Recipe.settings`) override its values. Plain data: the command
line reads it without loading torch.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from types import MappingProxyType
from typing import Any

from core.errors import BadInput
from train.model.config import CGNNConfig, Offsets
from train.training.train_params import Loss, TrainOptions


def _frozen(**values: Any) -> Mapping[str, Any]:
    return MappingProxyType(values)


@dataclass(frozen=True)
class Recipe:
    """A named set of training settings: ``options`` (fields of
    :class:`train.training.train_params.TrainOptions`) and ``network`` (fields of
    :class:`train.model.config.CGNNConfig`), each only where it differs from the paper."""

    name: str
    options: Mapping[str, Any] = field(default_factory=_frozen)
    network: Mapping[str, Any] = field(default_factory=_frozen)

    def settings(self, **given: Any) -> tuple[TrainOptions, CGNNConfig]:
        """The options and network of this recipe, the ``given`` fields (of either) in place
        of the recipe's; a name that is neither's field is a programming error (TypeError),
        a setting out of its bounds or a network that cannot be (offsets without the
        condition) bad input (:class:`TrainOptions`, :class:`CGNNConfig`)."""
        opt_names = {f.name for f in fields(TrainOptions)}
        net_names = {f.name for f in fields(CGNNConfig)}
        strange = set(given) - opt_names - net_names
        if strange:
            raise TypeError(f"not a training setting: {sorted(strange)}")
        options = {**self.options, **{k: v for k, v in given.items() if k in opt_names}}
        network = {**self.network, **{k: v for k, v in given.items() if k in net_names}}
        return TrainOptions(**options), CGNNConfig(**network)

    def flags(self) -> tuple[str, ...]:
        """The recipe as ``pipeline train`` options (its help; what it is short for)."""
        out: list[str] = []
        for name, value in {**self.network, **self.options}.items():
            flag = "--" + name.replace("_", "-")
            out += [flag] if value is True else [flag, f"{value:g}" if isinstance(
                value, float) else str(value)]
        return tuple(out)


PAPER = Recipe("paper")
OURS = Recipe("ours", options=_frozen(loss=Loss.BALANCED, rotate=True, ema=0.99, lr=2e-3),
              network=_frozen(offsets=Offsets.HEADS))
RECIPES: Mapping[str, Recipe] = MappingProxyType({r.name: r for r in (PAPER, OURS)})


def recipe(name: str) -> Recipe:
    """The recipe called ``name``; an unknown name is bad input."""
    if name not in RECIPES:
        raise BadInput(None, f"--recipe {name!r}: not one of {', '.join(RECIPES)}")
    return RECIPES[name]

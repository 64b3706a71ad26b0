"""Every setting of ``pipeline eval``, with its choices and bounds (the command line reads
them here)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import ClassVar

from core.bounds import Bound, check_bounds
from core.errors import BadInput
from train.evaluation.lump import Lump, lump_from_truth, parse_lump

DEVICES = ("cpu", "cuda")      # where the runs are scored (and the scarcity runs retrained)


@dataclass(frozen=True)
class EvalParams:
    """Every setting of an evaluation: the device, the data-scarcity study (retrain on
    1..``scarcity_groups`` training groups for ``scarcity_epochs``; None: all, the run's),
    and a lump to evaluate over (``lump``, or a twin's ``truth``; :mod:`train.evaluation.lump`);
    bad input, in one line naming the setting, where one is out of its bounds."""

    device: str = DEVICES[0]
    scarcity: bool = False
    scarcity_epochs: int | None = None
    scarcity_groups: int | None = None
    lump: str | None = None            # "X,Y,R" mm: evaluate over it and away from it
    truth: Path | None = None          # a twin's truth.h5: its first inclusion is the lump

    BOUNDS: ClassVar[Mapping[str, Bound]] = MappingProxyType({
        "scarcity_epochs": Bound(1, whole=True),
        "scarcity_groups": Bound(1, whole=True),
    })

    def __post_init__(self) -> None:
        if self.device not in DEVICES:
            raise BadInput(None, f"device {self.device!r}: must be one of {', '.join(DEVICES)}")
        check_bounds(self, self.BOUNDS)
        if self.lump is not None and self.truth is not None:
            raise BadInput("--lump", "names the lump by hand: leave out --truth, or --lump")
        if self.lump is not None:
            parse_lump(self.lump)

    def the_lump(self) -> Lump | None:
        """The lump asked for: ``lump`` parsed, or the ``truth``'s first inclusion."""
        if self.lump is not None:
            return parse_lump(self.lump)
        return None if self.truth is None else lump_from_truth(self.truth)

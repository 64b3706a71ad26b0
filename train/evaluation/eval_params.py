"""Every setting of ``pipeline eval``, with its choices and bounds (the command line reads
them here)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import ClassVar

from core.bounds import Bound, check_bounds
from core.errors import BadInput

DEVICES = ("cpu", "cuda")      # where the runs are scored (and the scarcity runs retrained)


@dataclass(frozen=True)
class EvalParams:
    """Every setting of an evaluation: the device, and the data-scarcity study (retrain on
    1..``scarcity_groups`` training groups for ``scarcity_epochs``; None: all, the run's);
    bad input, in one line naming the setting, where one is out of its bounds."""

    device: str = DEVICES[0]
    scarcity: bool = False
    scarcity_epochs: int | None = None
    scarcity_groups: int | None = None

    BOUNDS: ClassVar[Mapping[str, Bound]] = MappingProxyType({
        "scarcity_epochs": Bound(1, whole=True),
        "scarcity_groups": Bound(1, whole=True),
    })

    def __post_init__(self) -> None:
        if self.device not in DEVICES:
            raise BadInput(None, f"device {self.device!r}: must be one of {', '.join(DEVICES)}")
        check_bounds(self, self.BOUNDS)

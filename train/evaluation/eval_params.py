"""Every setting of ``pipeline eval``."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class EvalParams:
    """Every setting of an evaluation: the device, and the data-scarcity study (retrain on
    1..``scarcity_groups`` training groups for ``scarcity_epochs``; None: all, the run's)."""

    device: str = "cpu"
    scarcity: bool = False
    scarcity_epochs: int | None = None
    scarcity_groups: int | None = None

"""Every setting of ``pipeline split``, and the data's defaults where the user gives none.

The fields' defaults are the command line's: ``pipeline/split_cmd.py`` reads them here.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import ClassVar

from core.bounds import Bound, check_bounds
from core.errors import BadInput

GROUPINGS = ("sequence", "location")    # whole presses, or whole places, in one role
# by the states file's source: the grouping and the train:val:test ratio (the paper's for
# lab presses; by place for the simulators, MSM, a lab's solid and a prior's moulds, whose
# locations are their presses' places)
DEFAULTS = {"lab": ("sequence", (12, 3, 5)), "msm": ("location", (7, 2, 1)),
            "solid": ("location", (7, 2, 1)), "moulds": ("location", (7, 2, 1))}


@dataclass(frozen=True)
class SplitParams:
    """Every setting of ``pipeline split``: None where the data's default (:data:`DEFAULTS`,
    by the states file's source) applies. The runner fills those in before it splits, and
    the manifest's provenance records the settings so completed. Bad input, in one line
    naming the setting, where one is out of its bounds."""

    group_by: str | None = None                     # sequence | location
    ratio: tuple[int, int, int] | None = None       # train:val:test group counts
    folds: int = 5
    seed: int = 0

    BOUNDS: ClassVar[Mapping[str, Bound]] = MappingProxyType({"folds": Bound(1, whole=True)})

    def __post_init__(self) -> None:
        if self.group_by is not None and self.group_by not in GROUPINGS:
            raise BadInput(None, f"group_by {self.group_by!r}: must be one of "
                                 f"{', '.join(GROUPINGS)}")
        if self.ratio is not None:
            check_ratio(self.ratio, ":".join(map(str, self.ratio)))
        check_bounds(self, self.BOUNDS)


def filled_in(plan: SplitParams) -> tuple[str, tuple[int, int, int]]:
    """The grouping and the ratio of a plan whose data's defaults are filled in (by the
    runner, before it splits); a plan without them is a programming error."""
    if plan.group_by is None or plan.ratio is None:
        raise ValueError("a split plan needs its grouping and ratio filled in from the data")
    return plan.group_by, plan.ratio


def check_ratio(ratio: tuple[int, ...], text: str) -> None:
    """Refuse a train:val:test ratio (written ``text``) that is not three counts, the train and
    test ones positive."""
    if len(ratio) != 3 or min(ratio) < 0 or ratio[0] < 1 or ratio[2] < 1:
        raise BadInput(None, f"--ratio must be TRAIN:VAL:TEST with positive train and test "
                             f"counts, got {text!r}")

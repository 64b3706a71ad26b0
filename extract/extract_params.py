"""Every setting of ``pipeline extract``.

The fields' defaults are the command line's: ``pipeline/extract_cmd.py`` reads them here. The
provenance of the states file records them all.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import ClassVar

from core.bounds import Bound, check_bounds
from core.protocol import FOOTPRINT_SIDE, STEP_N


@dataclass(frozen=True)
class ExtractParams:
    """Every setting of ``pipeline extract``: how states are read off a press, and how the
    sessions become one states file; bad input, in one line naming the setting, where one is
    out of its bounds (the step against the data's noise and peak: when it is read)."""

    step_n: float = STEP_N         # force level spacing, N
    half_window_s: float = 0.02    # frames within this of the crossing are fitted
    rest_window_s: float = 0.1     # k = 0: the frames this long before onset
    max_speed: float | None = None  # m/s: states faster than this are dropped
    min_samples: int = 3           # finite frames a point needs in the window to be valid
    seed: int = 0                  # the multi-step examples' draw
    size_m: tuple[float, float] | None = None   # footprint (L, W) m over the synced files'
    shared_locations: bool = False  # the files' location ids name the same places

    BOUNDS: ClassVar[Mapping[str, Bound]] = MappingProxyType({
        "step_n": Bound(0, min_open=True, unit="N"),
        "half_window_s": Bound(0, min_open=True, unit="s"),
        "rest_window_s": Bound(0, min_open=True, unit="s"),
        "max_speed": Bound(0, min_open=True, unit="m/s"),
        "min_samples": Bound(1, whole=True),
        "size_m": FOOTPRINT_SIDE,
    })

    def __post_init__(self) -> None:
        check_bounds(self, self.BOUNDS)

"""Every setting of the sync stage, and the check that each one has a meaning.

The fields' defaults are the command line's: ``pipeline/sync_cmd.py`` reads them here.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import ClassVar

from core.bounds import Bound, check_bounds
from core.errors import BadInput

CLOCKS = ("auto", "trigger", "data")   # the clock alignments --clock names


@dataclass(frozen=True)
class SyncParams:
    """Every setting of the sync stage (stored in the output's provenance); bad input, in one
    line naming the setting, where one is out of its bounds."""

    clock: str = CLOCKS[0]           # auto (trigger when recorded, else data) | trigger | data
    max_gap_s: float = 0.020         # longest marker gap filled
    margin_s: float = 0.5            # unloaded frames kept before onset and after release
    detect_n: float = 0.5            # a press must rise above this force
    contact_n: float = 0.05          # contact level (raised to 5 noise widths if need be)
    location_radius_m: float = 0.010  # presses closer than this share a location
    max_offset_s: float | None = None  # data clock: largest offset searched (None: every
    #                                    lag at which the recordings overlap, any stamps)
    passband: float = 0.8            # resampler flat to this fraction of the mocap Nyquist
    max_fit_rms_m: float = 1.0e-3    # rigid fits with a larger residual are poor
    robust_scale_m: float = 0.3e-3   # Cauchy reweighting of the cluster fit (0: plain LS)
    tip_cutoff_hz: float = 15.0      # zero-phase low-pass of the tip track (0: off)
    min_pivot_rotation_deg: float = 5.0
    min_correlation: float = 0.5     # data-driven clock: force must follow the depth this well
    retare: bool = True              # re-tare from the rest next to every press (False: start)

    # > 0, or >= 0 where 0 means off (or none); the command line's options read them here
    BOUNDS: ClassVar[Mapping[str, Bound]] = MappingProxyType({
        "max_gap_s": Bound(0, unit="s"),
        "margin_s": Bound(0, unit="s"),
        "robust_scale_m": Bound(0, unit="m"),
        "tip_cutoff_hz": Bound(0, unit="Hz"),
        "location_radius_m": Bound(0, min_open=True, unit="m"),
        "detect_n": Bound(0, min_open=True, unit="N"),
        "contact_n": Bound(0, min_open=True, unit="N"),
        "max_fit_rms_m": Bound(0, min_open=True, unit="m"),
        "max_offset_s": Bound(0, min_open=True, unit="s"),
        "passband": Bound(0, 1, min_open=True, max_open=True),
    })

    def __post_init__(self) -> None:
        check_params(self)


def check_params(p: SyncParams) -> None:
    """Refuse settings outside their meaning (the CLI checks its options the same way)."""
    if p.clock not in CLOCKS:
        raise BadInput(None, f"clock {p.clock!r}: must be one of {', '.join(CLOCKS)}")
    check_bounds(p, p.BOUNDS)

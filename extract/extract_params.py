"""Every setting of ``pipeline extract``.

The fields' defaults are the command line's: ``pipeline/extract_cmd.py`` reads them here. The
provenance of the states file records them all.
"""

from __future__ import annotations

from dataclasses import dataclass

from core.protocol import STEP_N


@dataclass(frozen=True)
class ExtractParams:
    """Every setting of ``pipeline extract``: how states are read off a press, and how the
    sessions become one states file."""

    step_n: float = STEP_N         # force level spacing, N
    half_window_s: float = 0.02    # frames within this of the crossing are fitted
    rest_window_s: float = 0.1     # k = 0: the frames this long before onset
    max_speed: float | None = None  # m/s: states faster than this are dropped
    min_samples: int = 3           # finite frames a point needs in the window to be valid
    seed: int = 0                  # the multi-step examples' draw
    size_m: tuple[float, float] | None = None   # footprint (L, W) m over the synced files'
    shared_locations: bool = False  # the files' location ids name the same places

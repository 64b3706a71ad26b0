"""The levels an interval table holds, and a level asked as its index among them.

A table holds 0.01 .. 0.99 in steps of 0.01; a level between two takes the next above (the
interval is then at least as wide as asked). A caller resolves a level once
(:func:`level_index`) and passes the index on.
"""

from __future__ import annotations

import math
from functools import lru_cache

LEVELS = tuple(round(0.01 * i, 2) for i in range(1, 100))   # the levels a table holds
REPORTED = (0.8, 0.9, 0.95)                                   # what evaluation reports


def level_index(level: float) -> int:
    """The index in :data:`LEVELS` of ``level`` (the next level above it where it lies
    between two); ValueError in one line outside (0, 1) or above the highest."""
    try:
        return _level_index(level)
    except TypeError:                  # unhashable: no level
        raise ValueError(f"level must lie in (0, 1), got {level!r}") from None


@lru_cache(maxsize=256)
def _level_index(level: float) -> int:
    """:func:`level_index`, kept per level asked (a haptic loop asks one, call after call)."""
    if not (isinstance(level, int | float) and math.isfinite(level) and 0 < level < 1):
        raise ValueError(f"level must lie in (0, 1), got {level!r}")
    i = max(math.ceil(round(level * 100, 9)) - 1, 0)
    if i >= len(LEVELS):
        raise ValueError(f"level {level:g}: intervals are calibrated up to {LEVELS[-1]:g}")
    return i

"""The indentation protocol's numbers that lab stages and simulators share, each stated once.

- :data:`STEP_N`: static states every 0.5 N. The paper extracts its lab states at every 0.5 N
  and loads the MSM to 7.5 N in 15 equal steps of it; extract's ``--step`` default, the twin's
  true states and the MSM protocol all take it from here. A states file records the spacing it
  was made with (root attribute ``step_n``), so a reader computes a state's force level as
  ``step * step_n`` from the file, never from this constant.
- :data:`FOOTPRINT_M`: the phantom's footprint in the phantom frame by default, 100 x 100 mm
  (the paper's phantom, the MSM's grid): extract centres the marker grid on it.
- :data:`FOOTPRINT_SIDE`: a footprint side's bounds: no phantom pressed by hand is larger than
  2 m (the states file's limit of plausible metres is 5 m).
- :data:`THICKNESS_M`: the phantom's thickness, 32 mm (the twin's block): a surface pressed
  deeper than this went through the phantom (simulate counts the MSM's states beyond it).

- :func:`top_level`, :func:`reaches`: the highest level a force reaches, ``floor(force /
  step)`` with room for the rounding of a force that lands on a level (7.5 N / 0.5 N is level
  15, not 14): a force :data:`LEVEL_ROUNDING` of a step short of a level is on it.

Plain numbers and the standard library: command-line defaults read them without loading a
stage.
"""

import math
from typing import Any

from core.bounds import Bound

STEP_N = 0.5                     # N between force levels
FOOTPRINT_M = (0.1, 0.1)         # m, width and length of the phantom's footprint
FOOTPRINT_SIDE = Bound(0, 2.0, min_open=True, unit="m")   # each side of a footprint
THICKNESS_M = 0.032              # m, the phantom block's thickness
LEVEL_ROUNDING = 1e-9            # of a step: a force this short of a level is on it


def top_level(force_n: float, step_n: float) -> int:
    """The highest force level (index k of ``k * step_n``) that ``force_n`` reaches
    (:func:`reaches`)."""
    return math.floor(force_n / step_n + LEVEL_ROUNDING)


def reaches(force_n: Any, level: int, step_n: float) -> Any:
    """Whether each force reaches level ``level`` (``level * step_n``); a force short of it
    by less than :data:`LEVEL_ROUNDING` of a step (rounding) counts as on it. The one test
    :func:`top_level` and a crossing both make, so a level counted as reached is crossed."""
    return force_n / step_n + LEVEL_ROUNDING >= level   # a float or a numpy array alike

"""A level asked as its index among the table's: the level itself where the table holds it,
the next above where it lies between two, refused in one line outside (0, 0.99]."""

from __future__ import annotations

import numpy as np
import pytest

from train.intervals.levels import LEVELS, level_index


def test_levels_refused_in_one_line() -> None:
    assert LEVELS[level_index(0.9)] == 0.9 and LEVELS[level_index(0.8)] == 0.8
    assert LEVELS[level_index(0.905)] == 0.91                 # the next level above
    assert LEVELS[level_index(0.001)] == 0.01
    for bad in (0.0, 1.0, -0.1, 1.5, float("nan"), "0.9", [0.9], np.array(0.9)):
        with pytest.raises(ValueError, match=r"level must lie in \(0, 1\)"):
            level_index(bad)
    with pytest.raises(ValueError, match="calibrated up to 0.99"):
        level_index(0.995)

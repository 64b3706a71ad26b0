"""The table's plain form: what a checkpoint made before this package holds (spelled out by
hand in tests/helpers/interval_table.py) is read, with its radii where the bins put them; a
table survives JSON with an unbounded bin; a table whose shapes or levels disagree is
refused."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers.interval_table import near_far, stored_table

from train.intervals.levels import level_index
from train.intervals.table import IntervalTable


def test_a_stored_table_is_read_as_it_was_written() -> None:
    table = IntervalTable.from_dict(stored_table())
    i = level_index(0.9)
    np.testing.assert_array_equal(table.radii(i, np.array([0.0, 0.0099, 0.01, 0.05]), 1e-3,
                                              0.0), [1e-3, 1e-3, 1e-4, 1e-4])
    assert np.isinf(table.radii(level_index(0.99), np.array([0.05]), 1e-3, 0.0)).all()
    assert table.force.widths(i, 2e-3, 1e-3) == 0.25
    assert (table.presses, table.examples) == (3, 50)
    assert table.to_dict() == stored_table()


def test_a_table_survives_json_with_an_unbounded_bin() -> None:
    rng = np.random.default_rng(2)
    scores, feats = near_far(rng, 500)
    table = IntervalTable.fit(scores, feats, rng.uniform(0, 1, 10),
                              rng.uniform(0, 1e-3, (10, 2)), presses=2)
    assert np.isinf(table.force.width[..., level_index(0.95)]).all()   # 10 examples
    back = IntervalTable.from_dict(json.loads(json.dumps(table.to_dict(), allow_nan=False)))
    np.testing.assert_array_equal(back.points.width, table.points.width)
    np.testing.assert_array_equal(back.force.width, table.force.width)
    bad = table.to_dict()
    bad["points"]["width"] = bad["points"]["width"][:1]
    with pytest.raises(ValueError, match="shape"):
        IntervalTable.from_dict(bad)


def test_levels_other_than_the_tables_are_refused() -> None:
    bad = stored_table()
    bad["levels"] = bad["levels"][:-1]
    with pytest.raises(ValueError, match="levels"):
        IntervalTable.from_dict(bad)

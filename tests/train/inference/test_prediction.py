"""A prediction is one type whatever the level: its fields, and the tuple it used to be. Without
a level it unpacks and indexes as (deformed, dforce), silently; with one, as the triple
(deformed, dforce, sure) it used to be, with a DeprecationWarning that names the fields."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from train.inference.prediction import Prediction
from train.intervals.lookup import Interval

POINTS = np.zeros((4, 3), np.float32)
SURE = Interval(0.9, np.full(4, 1e-3), (0.1, 0.5), True)


def test_without_a_level_it_is_the_pair_it_was() -> None:
    p = Prediction(POINTS, 0.3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        deformed, dforce = p
        assert deformed is POINTS and dforce == 0.3
        assert len(p) == 2 and p[0] is POINTS and p[1] == 0.3 and p[-1] == 0.3
    assert p.points is POINTS and p.dforce == 0.3 and p.sure is None


def test_with_a_level_the_triple_still_unpacks_but_warns() -> None:
    p = Prediction(POINTS, 0.3, SURE)
    assert p.sure is SURE and p.points is POINTS
    with pytest.warns(DeprecationWarning, match=r"read \.points, \.dforce and \.sure"):
        deformed, dforce, sure = p
    assert deformed is POINTS and dforce == 0.3 and sure is SURE
    with pytest.warns(DeprecationWarning):
        assert p[2] is SURE
    with pytest.raises(ValueError), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        deformed, dforce = p                                   # a triple, as before


def test_the_warning_points_at_the_callers_line() -> None:
    with pytest.warns(DeprecationWarning) as caught:
        _, _, _ = Prediction(POINTS, 0.3, SURE)
    assert caught[0].filename == __file__

"""The same place (data_schema/places.py): the states file's location ids, numbered in the
order first met; without ids, each press its own place."""

from __future__ import annotations

import numpy as np

from data_schema.places import place_ids


def test_places_follow_the_location_ids_in_the_order_first_met() -> None:
    np.testing.assert_array_equal(place_ids(np.array([12, 3, 12, 40, 3]), 5), [0, 1, 0, 2, 1])


def test_without_ids_each_press_is_its_own_place() -> None:
    np.testing.assert_array_equal(place_ids(None, 4), [0, 1, 2, 3])

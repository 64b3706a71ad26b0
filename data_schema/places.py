"""The same place on the phantom: one rule, the states file's location ids.

Sync names each press's location (a press joins the nearest location whose centre is within
``SyncParams.location_radius_m``, 10 mm by default, else opens one: sync/presses.py), extract
carries the ids into the states file (``states/location``, :mod:`data_schema.states`; per file
unless the files are said to share them), and simulate gives each loaded mass its own (the
MSM's location). Every reader that asks whether two presses were at the same place (fit-msm
--map's places, eval's test places on the footprint) reads those ids, never a distance of its
own. Every ``phantom.states`` file has them; only data made in memory without them fall back,
and then each press is a place of its own: no reader invents a grouping the file does not
state.
"""

from __future__ import annotations

import numpy as np


def place_ids(location: np.ndarray | None, count: int) -> np.ndarray:
    """Each of ``count`` presses' place (count,) int, numbered 0, 1, ... in the order the
    places are first met: the presses' location ids (``location``, (count,)), or where there
    are none, each press its own."""
    if location is None:
        return np.arange(count)
    ids = np.asarray(location).reshape(count)
    _, first, which = np.unique(ids, return_index=True, return_inverse=True)
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    return rank[which.ravel()]

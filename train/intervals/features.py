"""What the intervals' bins read of a press, measured one way for calibration and lookup alike.

A point's error depends on how far it lies from the tip's path (the segment tip start - tip
end), on the press's depth (|tip end - tip start|) and on how high the tip starts above the
surface. Calibration measures them with :func:`press_features`; a predictor's lookup
(:mod:`train.intervals.lookup`) with the three functions it is made of
(:func:`path_distance`, :func:`press_depth`, :func:`start_height`), in the same arithmetic,
so that a press looked up falls in the bins it was calibrated in to the last bit, a value on
a bin's edge included.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import overload

import numpy as np

from train.model.normalise import tip_height

POINT_FEATURES = ("distance", "depth", "height")   # a point's radius is binned by these
FORCE_FEATURES = ("depth", "height")               # the force's half-width by these


@dataclass(frozen=True)
class PressFeatures:
    """The features of presses (...): each point's distance from the tip's path (..., N) m,
    the press's depth (...) m and the tip start's height above the surface (...) m."""

    distance: np.ndarray
    depth: np.ndarray
    height: np.ndarray

    def of_points(self) -> np.ndarray:
        """Each point's features (..., N, 3), in :data:`POINT_FEATURES`' order."""
        press = np.broadcast_to(np.stack([self.depth, self.height], -1)[..., None, :],
                                (*self.distance.shape, 2))
        return np.concatenate([self.distance[..., None], press], -1)

    def of_force(self) -> np.ndarray:
        """Each press's features (..., 2), in :data:`FORCE_FEATURES`' order."""
        return np.stack([self.depth, self.height], -1)


def press_features(points: np.ndarray, valid: np.ndarray, condition: np.ndarray
                   ) -> PressFeatures:
    """The bins' features of presses: inputs (B, N, 3) m with validity (B, N) and
    C = [tip start, tip end] (B, 6) m, in float64 (the tip start's height is over each
    press's valid points)."""
    start, end = condition[:, :3], condition[:, 3:]
    height = [start_height(p[v], s) for p, v, s in zip(points, valid, start, strict=True)]
    return PressFeatures(path_distance(points, start, end), press_depth(condition.T),
                         np.array(height, dtype=np.float64))


def path_distance(points: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Distance (..., N) of each point (..., N, 3) from the segment ``start``-``end`` (..., 3)
    (from ``start`` where they coincide); elementwise, so one press's distances are the same
    alone as in a batch."""
    axis = (end - start)[..., None, :]
    rel = points - start[..., None, :]
    length2 = (axis * axis).sum(-1)
    t = np.clip((rel * axis).sum(-1) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
    return np.sqrt(((rel - t[..., None] * axis) ** 2).sum(-1))


@overload
def press_depth(c: np.ndarray) -> np.ndarray: ...
@overload
def press_depth(c: Sequence[float]) -> float: ...
def press_depth(c: Sequence[float] | np.ndarray) -> float | np.ndarray:
    """How far the tip moves, |tip end - tip start| (m), of C's six numbers along the first
    axis: a press's plain floats (a float back, in microseconds) or an array (6, ...) (an
    array (...) back), in the same arithmetic either way."""
    dx, dy, dz = c[3] - c[0], c[4] - c[1], c[5] - c[2]
    square = dx * dx + dy * dy + dz * dz
    return math.sqrt(square) if isinstance(square, float) else np.sqrt(square)


def start_height(points: np.ndarray, start: np.ndarray) -> float:
    """How high the tip ``start`` (3,) lies above the surface ``points`` (N, 3) m
    (:func:`train.model.normalise.tip_height`, the training envelope's measure); 0 where no
    other point is left."""
    height = tip_height(start, points)
    return 0.0 if math.isnan(height) else height

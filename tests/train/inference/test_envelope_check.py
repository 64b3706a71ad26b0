"""The per-call envelope check of a known scene. Known truth: a tip's height is
:func:`train.model.normalise.tip_height` over all the scene's points (its definition, which the
training envelope and the intervals' calibration measure), kept per tip asked, and a tip that
ties between two points takes the first of them, as the envelope's fit does; a press whose
start is within the limit above the scene's lowest point cannot be too high, and is not
searched."""

from __future__ import annotations

import numpy as np
import pytest

from train.inference.predictor import Scene
from train.model.normalise import tip_height


def _scene(points: np.ndarray) -> Scene:
    return Scene(points.astype(np.float32), np.zeros((len(points), 5), np.int64), 0.0)


def _surfaces() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(3)
    cloud = rng.uniform(0.0, 0.1, (300, 3))
    cloud[:, 2] *= 0.05
    g = np.linspace(0.0, 0.1, 32)
    x, y = np.meshgrid(g, g)
    bumpy = np.stack([x.ravel(), y.ravel(), rng.normal(0.0, 0.002, x.size)], 1)
    return {"cloud": cloud, "bumpy grid": bumpy, "26 points": cloud[:26]}


@pytest.mark.parametrize("name", list(_surfaces()))
def test_the_height_is_tip_height_over_every_point(name: str) -> None:
    """Tips anywhere, and on a point (the lab's tip marker, left out within 0.1 mm)."""
    points = _surfaces()[name].astype(np.float32)
    scene, rng = _scene(points), np.random.default_rng(4)
    tips = [rng.uniform(-0.01, 0.11, 3) for _ in range(200)]
    tips += [points[i] + rng.normal(0.0, 3e-5, 3) for i in rng.integers(0, len(points), 50)]
    for tip in tips:
        assert scene.height(tip) == tip_height(tip, points)


def test_a_tip_between_two_points_takes_the_first() -> None:
    """Two points at the same distance in x, y (exactly: binary fractions) and of different
    heights: the height is over the first of them, as the training envelope measures it."""
    points = np.array([[0.0, 0.0, 0.001], [0.5, 0.0, -0.001], [0.5, 0.5, 0.0],
                       [0.0, 0.5, 0.0], [0.25, 0.75, 0.0], [0.75, 0.25, 0.0]], np.float32)
    tip = np.array([0.25, 0.0, 0.004])
    assert _scene(points).height(tip) == 0.004 - float(np.float32(0.001))
    assert _scene(points[[1, 0, 2, 3, 4, 5]]).height(tip) == 0.004 - float(np.float32(-0.001))


def test_only_the_tip_leaves_no_height() -> None:
    points = np.zeros((6, 3), np.float32)
    assert np.isnan(_scene(points).height(np.zeros(3)))

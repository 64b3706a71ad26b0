"""The bins' features against known geometry (a point's Euclidean distance from a segment, a
press's length, a tip's height over a known surface), and one arithmetic for a batch of
presses (calibration) and a press alone (a predictor's lookup): the same bits either way."""

from __future__ import annotations

import numpy as np

from train.intervals.features import (
    path_distance,
    press_depth,
    press_features,
    start_height,
)


def test_path_distance_is_euclidean() -> None:
    pts = np.array([[0.0, 0, 0], [1, 0, 0], [0, 0, 2], [3, 4, -1]])
    start, end = np.array([0.0, 0, 0]), np.array([0.0, 0, -1])
    np.testing.assert_allclose(path_distance(pts, start, end), [0, 1, 2, 5])
    np.testing.assert_allclose(path_distance(pts, start, start), [0, 1, 2, np.sqrt(26)])


def test_the_depth_is_the_press_length_as_floats_or_arrays() -> None:
    assert press_depth([1.0, 2.0, 3.0, 4.0, 6.0, 15.0]) == 13.0
    rng = np.random.default_rng(0)
    c = rng.normal(0.0, 0.01, (2000, 6)).astype(np.float32).astype(np.float64)
    batch = press_depth(c.T)
    np.testing.assert_allclose(batch, np.linalg.norm(c[:, 3:] - c[:, :3], axis=1), rtol=1e-15)
    alone = np.array([press_depth(row.tolist()) for row in c])
    np.testing.assert_array_equal(alone, batch)


def test_the_height_is_over_the_nearest_other_point() -> None:
    """Over a surface at z = 1 mm (and one point at 3 mm, the tip's nearest in x, y), a tip
    at 5 mm is 2 mm above it; the tip's own marker (within 0.1 mm) is left out; with no
    other point there is no height: 0."""
    surface = np.array([[0.0, 0, 1e-3], [0.01, 0, 1e-3], [0.002, 0.001, 3e-3]])
    tip = np.array([0.002, 0.0, 5e-3])
    assert start_height(surface, tip) == 5e-3 - 3e-3
    assert start_height(np.vstack([surface, tip + 5e-5]), tip) == 5e-3 - 3e-3
    assert start_height(tip[None] + 5e-5, tip) == 0.0


def test_a_batch_of_presses_is_each_press_alone() -> None:
    """Calibration measures a batch with a validity mask; a lookup one press on all its
    points: each feature the same to the last bit, the height over the valid points only."""
    rng = np.random.default_rng(1)
    points = rng.uniform(0.0, 0.1, (5, 30, 3)).astype(np.float32).astype(np.float64)
    valid = rng.uniform(size=(5, 30)) > 0.2
    tips = rng.uniform(0.0, 0.1, (5, 3)) + [0, 0, 0.01]
    cond = np.c_[tips, tips - [0, 0, 0.004]].astype(np.float32).astype(np.float64)
    f = press_features(points, valid, cond)
    for b in range(5):
        c = cond[b].tolist()
        np.testing.assert_array_equal(f.distance[b], path_distance(
            points[b], np.array(c[:3]), np.array(c[3:])))
        assert f.depth[b] == press_depth(c)
        assert f.height[b] == start_height(points[b][valid[b]], np.array(c[:3]))
    assert f.of_points().shape == (5, 30, 3) and f.of_force().shape == (5, 2)
    np.testing.assert_array_equal(f.of_points()[2, 7], [f.distance[2, 7], f.depth[2],
                                                        f.height[2]])
    np.testing.assert_array_equal(f.of_force()[3], [f.depth[3], f.height[3]])

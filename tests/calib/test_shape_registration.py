"""Markers registered to a curved phantom's shape, against a known placement: markers laid on an
analytic dome (a sphere's cap: each centre its radius off the surface along the sphere's
normal), moved into the lab by a known rigid transform; registration must find that transform
back, and refuse by name a marker moved off the mould."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from calib.shape_registration import register_markers
from core.errors import BadInput
from data_schema.phantom import PhantomLayout
from sim.twin.twin_shape import dome

SIZE = (0.1, 0.1, 0.032)
HEIGHT = 0.03
MARKER_R = 1.5e-3


def _sphere() -> tuple[np.ndarray, float]:
    """The dome's sphere in its shape frame: centre and radius."""
    half = np.hypot(*SIZE[:2]) / 2
    radius = (half ** 2 + HEIGHT ** 2) / (2 * HEIGHT)
    return np.array([SIZE[0] / 2, SIZE[1] / 2, HEIGHT - radius]), radius


def _markers_on_dome() -> np.ndarray:
    """A 5 x 5 grid, 20 mm apart and centred, row-major along +x, resting on the cap."""
    centre, radius = _sphere()
    xs = SIZE[0] / 2 + np.arange(-2, 3) * 0.02
    ys = SIZE[1] / 2 + np.arange(-2, 3) * 0.02
    xy = np.array([(x, y) for y in ys for x in xs])
    z = centre[2] + np.sqrt(radius ** 2 - ((xy - centre[:2]) ** 2).sum(axis=1))
    on = np.c_[xy, z]
    normal = (on - centre) / radius
    return on + MARKER_R * normal


def _lab(points: np.ndarray, to_shape: np.ndarray) -> np.ndarray:
    back = np.linalg.inv(to_shape)
    return points @ back[:3, :3].T + back[:3, 3]


@pytest.fixture(scope="module")
def case():
    shape = dome(SIZE, HEIGHT, "dome:30")
    layout = PhantomLayout(size_m=SIZE[:2], shape=shape.shape, marker_diameter_m=2 * MARKER_R)
    to_shape = np.eye(4)
    to_shape[:3, :3] = Rotation.from_euler("zyx", [7.0, 2.0, -3.0], degrees=True).as_matrix()
    to_shape[:3, 3] = [0.21, -0.34, 0.05]
    rng = np.random.default_rng(0)
    rest = _markers_on_dome()
    frames = _lab(rest, to_shape)[None] + rng.normal(0, 0.05e-3, (40, len(rest), 3))
    up = np.tile(to_shape[2, :3], (40, 1)) * 0.1           # the shaft: along the shape's +z
    names = [f"P{k:02d}" for k in range(len(rest))]
    return shape, layout, to_shape, frames, up, names


def test_registration_finds_the_true_placement(case) -> None:
    _, layout, to_shape, frames, up, names = case
    reg = register_markers(frames, up, names, layout, "s.tsv")
    rest = _markers_on_dome()
    moved = reg.to_shape @ np.linalg.inv(to_shape)         # true shape frame -> ours
    err = rest @ moved[:3, :3].T + moved[:3, 3] - rest
    assert np.linalg.norm(err, axis=1).max() < 0.05e-3
    assert np.nanmax(np.abs(reg.residual)) < 0.1e-3


def test_a_marker_off_the_mould_is_refused_by_name(case) -> None:
    _, layout, to_shape, frames, up, names = case
    moved = frames.copy()
    moved[:, 12] += 3e-3 * to_shape[2, :3]                # P12 lifted 3 mm off the cap
    with pytest.raises(BadInput) as e:
        register_markers(moved, up, names, layout, "s.tsv")
    assert "P12" in str(e.value) and "off the registered shape" in str(e.value)


def test_markers_that_fix_the_axis_never_seen_are_refused(case) -> None:
    """A grid whose rows' last markers are never seen gives no +x: one line, no traceback."""
    _, layout, _, frames, up, names = case
    hidden = frames.copy()
    hidden[:, 4::5] = np.nan                               # each row's last marker
    with pytest.raises(BadInput, match="never seen at rest"):
        register_markers(hidden, up, names, layout, "s.tsv")

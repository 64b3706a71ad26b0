"""A curved phantom's markers registered to its shape: the rigid transform from the lab to the
shape's frame, and how far each marker rests off the surface.

On a flat phantom the rest plane fixes depth and tilt, and the layout (its rows or ``x_axis``,
its anchor or the markers' centroid) fixes the rest (:mod:`calib.rest_plane`,
:mod:`extract.phantom_frame`). On a curved one the surface fixes what its curvature can
(a dome: its height and tilt; a cylinder: all but the slide along its axis), and the same
layout fixes what it cannot. The markers' rest positions (medians over the session) are fitted
by least squares of both: each marker's distance to the surface less its radius (the centre of
a sphere glued on the surface), and the layout's origin and +x axis in the shape's frame, both
in metres. A marker resting farther than :data:`MAX_OFF_M` off the registered surface is
refused by name: the markers do not sit on this mould, or this one has moved.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from core.errors import BadInput
from data_schema.phantom import PhantomLayout
from data_schema.shape import Shape

MAX_OFF_M = 2e-3        # a marker at rest this far off the registered surface is refused
ROBUST_M = 0.5e-3       # beyond this a marker's residual counts less (soft L1): one bad marker
                        # does not drag the others off the mould


@dataclass(frozen=True)
class Registration:
    """Lab -> shape frame (4, 4), and each marker's rest distance off the surface less its
    radius (N,) in metres (NaN: never seen at rest)."""

    to_shape: np.ndarray
    residual: np.ndarray


def register_markers(phantom: np.ndarray, up: np.ndarray, names: list[str],
                     layout: PhantomLayout, source: str | Path) -> Registration:
    """The markers' rest positions (medians of ``phantom`` (T, N, 3), lab) registered to
    ``layout.shape``; ``up`` (T, 3) the indenter's shaft, tip to cluster, which stands above
    the surface and so says which side of the markers is out of the phantom."""
    shape = layout.shape
    assert shape is not None, "a flat phantom has a rest plane, not a registration"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        rest = np.nanmedian(phantom, axis=0)
    seen = np.isfinite(rest).all(axis=1)
    if seen.sum() < 3:
        raise BadInput(source, "fewer than 3 phantom markers were ever seen: no surface")
    start = _first_guess(rest, seen, up, names, layout, shape, source)
    radius = layout.marker_diameter_m / 2
    lever = float(np.hypot(*layout.size_m)) / 2   # an angle's worth of metres at the edge

    def residuals(x: np.ndarray) -> np.ndarray:
        moved = _apply(_moved(start, x), rest)
        off = shape.closest(moved[seen])[2] - radius
        origin, at = layout.origin(moved, names)
        x_dir = _unit_mean(layout.along_x(moved, names)[0][:, :2])
        return np.concatenate([off, origin[:2] - np.asarray(at), lever * (x_dir - [1.0, 0.0])])

    fit = least_squares(residuals, np.zeros(6), loss="soft_l1", f_scale=ROBUST_M,
                        x_scale=np.r_[np.full(3, 0.01), np.full(3, 1e-3)])
    to_shape = _moved(start, fit.x)
    residual = np.full(len(rest), np.nan)
    residual[seen] = shape.closest(_apply(to_shape, rest[seen]))[2] - radius
    _check_on_surface(residual, names, source)
    return Registration(to_shape=to_shape, residual=residual)


def _first_guess(rest: np.ndarray, seen: np.ndarray, up: np.ndarray, names: list[str],
                 layout: PhantomLayout, shape: Shape, source: str | Path) -> np.ndarray:
    """Lab -> shape frame as a flat phantom's frame would be: the markers' best plane's normal
    (turned toward ``up``) to +z, the layout's +x to +x and its origin to its place, resting on
    the surface there."""
    centre = rest[seen].mean(axis=0)
    z = np.linalg.svd(rest[seen] - centre)[2][2]
    along_up = up @ z
    if np.nanmedian(along_up[np.isfinite(along_up)]) < 0:
        z = -z
    along, what = layout.along_x(rest, names)
    if not np.isfinite(along).all(axis=1).any():
        raise BadInput(source, f"{what}: never seen at rest, no in-plane axis")
    x = _unit_mean(along)
    x = x - (x @ z) * z
    x /= np.linalg.norm(x)
    rot = np.stack([x, np.cross(z, x), z])
    origin, at = layout.origin(rest, names)
    top = shape.height(np.array([at]))[0]
    top = float(np.nanmax(shape.vertices[:, 2])) if not np.isfinite(top) else top
    out = np.eye(4)
    out[:3, :3] = rot
    out[:3, 3] = np.array([at[0], at[1], top]) - rot @ origin
    return out


def _moved(start: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``start`` followed by a small rotation (rotation vector ``x[:3]``, about the shape
    frame's origin) and a translation ``x[3:]``."""
    step = np.eye(4)
    step[:3, :3] = Rotation.from_rotvec(x[:3]).as_matrix()
    step[:3, 3] = x[3:]
    return step @ start


def _apply(t: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p @ t[:3, :3].T + t[:3, 3]


def _unit_mean(v: np.ndarray) -> np.ndarray:
    m = v[np.isfinite(v).all(axis=1)].mean(axis=0)
    return m / np.linalg.norm(m)


def _check_on_surface(residual: np.ndarray, names: list[str], source: str | Path) -> None:
    off = np.where(np.isfinite(residual), np.abs(residual), 0.0)
    k = int(np.argmax(off))
    if off[k] > MAX_OFF_M:
        raise BadInput(source, f"phantom marker {names[k]} rests {off[k] * 1e3:.1f} mm off the "
                               f"registered shape, beyond {MAX_OFF_M * 1e3:g} mm: it is not on "
                               "this mould (or the marker moved)")

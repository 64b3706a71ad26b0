"""The phantom frame: lab points moved onto the rest surface sync found, axes from the markers.

Lab and MSM states share one frame (rest surface at z = 0, +z out of the phantom, footprint
on [0, L] x [0, W]) so that a location means the same place in both. The rest plane itself
is sync's (:func:`sync.surface.rest_plane`, stored in the synced file's calibration).
"""

from __future__ import annotations

import numpy as np

from core.errors import BadInput


def grid_x_axis(rest: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """In-plane unit x axis of the marker grid: along each row, from its first to its last
    marker, averaged over rows (markers listed row-major, rows along +x, as in session.toml).

    A layout that is not a square grid takes the first to the last marker. Fixed by the
    markers' order, never by an SVD's sign.
    """
    m = len(rest)
    g = int(round(np.sqrt(m)))
    if g * g == m and g > 1:
        grid = rest.reshape(g, g, 3)
        along = grid[:, -1] - grid[:, 0]
    else:
        along = (rest[-1] - rest[0])[None]
    along = along[np.isfinite(along).all(axis=1)]
    if along.size == 0:
        raise BadInput(None, "no row of the marker grid was seen whole: no in-plane axis")
    x = along.mean(axis=0)
    x = x - (x @ normal) * normal
    norm = np.linalg.norm(x)
    if norm < 1e-9:
        raise BadInput(None, "the marker grid's rows run along the surface normal")
    return x / norm


def to_phantom_frame(rest: np.ndarray, surface_point: np.ndarray, normal: np.ndarray,
                     size_m: tuple[float, float]) -> np.ndarray:
    """4x4 transform lab -> phantom frame: the rest plane at z = 0 with +z along ``normal``
    (out of the phantom), x along the marker rows, and the marker grid's centre at the
    footprint's centre (size_m / 2): the markers are laid out centred on the phantom."""
    z = normal / np.linalg.norm(normal)
    x = grid_x_axis(rest, z)
    y = np.cross(z, x)
    rot = np.stack([x, y, z])                                      # rows: lab -> phantom
    seen = rest[np.isfinite(rest).all(axis=1)]
    centre = seen.mean(axis=0)
    centre = centre - ((centre - surface_point) @ z) * z           # onto the rest plane
    out = np.eye(4)
    out[:3, :3] = rot
    out[:3, 3] = np.array([size_m[0] / 2, size_m[1] / 2, 0.0]) - rot @ centre
    return out


def apply_transform(transform: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points (..., 3) through a 4x4 transform."""
    return points @ transform[:3, :3].T + transform[:3, 3]

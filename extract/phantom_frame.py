"""The phantom frame: lab points moved onto the rest surface sync found, axes from the markers.

Lab and MSM states share one frame (rest surface at z = 0, +z out of the phantom, footprint
on [0, L] x [0, W]) so that a location means the same place in both. The rest plane itself
is sync's (:func:`calib.rest_plane.rest_plane`, stored in the synced file's calibration); the
in-plane axis and the origin come from the phantom's layout (session.toml's ``[phantom]``,
:mod:`data_schema.phantom`, stored in the synced file's ``phantom`` attribute).
"""

from __future__ import annotations

import numpy as np

from core.errors import BadInput
from data_schema.phantom import PhantomLayout

ROW_OFF_M = 2e-3         # a grid's marker lies at most this far off its row's line
ROW_ANGLE_DEG = 10.0     # and every row runs within this of their mean direction


def x_axis(rest: np.ndarray, names: list[str], normal: np.ndarray,
           layout: PhantomLayout) -> np.ndarray:
    """In-plane unit x axis: from ``layout.x_axis``'s first marker to its second, or along the
    rows of the marker grid (``layout.rows`` rows, or a square grid), from each row's first to
    its last marker, averaged over rows (markers listed row-major, rows along +x).

    Fixed by the markers' names and order, never by an SVD's sign.
    """
    along, what = layout.along_x(rest, names)
    if layout.x_axis is None:
        _check_rows(rest.reshape(len(along), -1, 3), normal)
    along = along[np.isfinite(along).all(axis=1)]
    if along.size == 0:
        raise BadInput(None, f"{what}: never seen at rest, no in-plane axis")
    x = along.mean(axis=0)
    x = x - (x @ normal) * normal
    norm = np.linalg.norm(x)
    if norm < 1e-9:
        raise BadInput(None, f"{what} run along the surface normal: no in-plane axis")
    return x / norm


def _check_rows(grid: np.ndarray, normal: np.ndarray) -> None:
    """Refuse markers that are not the rows the layout says: each row's markers on one line
    (within :data:`ROW_OFF_M`) and every row along one direction (within
    :data:`ROW_ANGLE_DEG`); a 4 x 9 grid read as 6 x 6, or a scattered layout read as a grid,
    would turn the whole frame."""
    dirs = []
    for r, row in enumerate(grid):
        row = row[np.isfinite(row).all(axis=1)]
        if len(row) < 2:
            continue
        d = row[-1] - row[0]
        d = d - (d @ normal) * normal
        d /= max(np.linalg.norm(d), 1e-12)
        rel = row - row[0]
        off = np.linalg.norm(rel - np.outer(rel @ d, d) - np.outer(rel @ normal, normal), axis=1)
        if off.max() > ROW_OFF_M:
            raise BadInput(None, f"row {r} of the marker grid ({len(grid)} rows, listed "
                                 f"row-major) is not a line: a marker lies {off.max() * 1e3:.1f} "
                                 "mm off it; say the layout in session.toml ([phantom] rows = R, "
                                 "or x_axis = two markers)")
        dirs.append(d)
    if len(dirs) > 1:
        mean = np.mean(dirs, axis=0)
        mean /= np.linalg.norm(mean)
        worst = float(np.degrees(np.arccos(np.clip(min(d @ mean for d in dirs), -1, 1))))
        if worst > ROW_ANGLE_DEG:
            raise BadInput(None, f"the marker grid's rows run {worst:.0f} degrees apart: not the "
                                 f"{len(grid)} rows of a grid; say the layout in session.toml "
                                 "([phantom] rows = R, or x_axis = two markers)")


def to_phantom_frame(rest: np.ndarray, names: list[str], surface_point: np.ndarray,
                     normal: np.ndarray, layout: PhantomLayout) -> np.ndarray:
    """4x4 transform lab -> phantom frame: the rest plane at z = 0 with +z along ``normal``
    (out of the phantom), x from the layout (:func:`x_axis`), and the origin where the layout
    puts it: its anchor marker at ``anchor_m``, or the markers' centroid at the footprint's
    centre (markers laid out centred on the phantom)."""
    z = normal / np.linalg.norm(normal)
    x = x_axis(rest, names, z, layout)
    rot = np.stack([x, np.cross(z, x), z])                         # rows: lab -> phantom
    centre, at = layout.origin(rest, names)
    centre = centre - ((centre - surface_point) @ z) * z           # onto the rest plane
    out = np.eye(4)
    out[:3, :3] = rot
    out[:3, 3] = np.array([at[0], at[1], 0.0]) - rot @ centre
    return out


def apply_transform(transform: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points (..., 3) through a 4x4 transform."""
    return points @ transform[:3, :3].T + transform[:3, 3]

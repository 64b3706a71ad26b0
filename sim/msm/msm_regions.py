"""A stiffness map over the MSM's surface: a coarse grid of regions, one factor each.

A phantom that is not uniform (a stiffer lump, :mod:`sim.twin.material_regions`) is stiffer
in places. The MSM carries that as a map: the footprint ``[0, L] x [0, W]`` cut into ``R``
rows (along y) of ``C`` regions (along x) of equal size, each with a factor on the uniform
springs. A mass takes its region's factor on its ``k_fixed``; a spring between two masses the
mean of theirs on its ``k_between``. A factor of 1 everywhere is the uniform MSM; a region
``f`` times as stiff has both its spring kinds scaled by ``f``. A mass on a boundary between
regions belongs to the region of larger x (larger y); the last row and column take the far
edges.

A map is written row by row, ``R`` rows of ``C`` factors (``factors[i][j]``: the region of
the i-th y band and the j-th x band), as ``MSMParams.stiffness_map`` and in fit-msm's JSON.
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np

from core.errors import BadInput

MAX_REGIONS = 64          # 8 x 8: a finer map asks more of the presses than they can tell
MIDDLE = 0.375            # a place this far from a region's centre (share of its size, per
                          # axis) is in its middle: a grid whose boundaries run through the
                          # places would be told apart by the tips' noise alone


def parse_regions(text: str, option: str = "--regions") -> tuple[int, int]:
    """``RxC`` (rows along y, regions per row along x), each at least 1 and at most
    :data:`MAX_REGIONS` in all, else one line naming ``option``."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", str(text))
    if not m or int(m[1]) < 1 or int(m[2]) < 1 or int(m[1]) * int(m[2]) > MAX_REGIONS:
        raise BadInput(option, f"{text!r}: must be RxC, R rows (along y) of C regions (along "
                               f"x), e.g. 3x3, at most {MAX_REGIONS} regions")
    return int(m[1]), int(m[2])


def check_map(factors: Any, what: str = "stiffness_map") -> tuple[tuple[float, ...], ...]:
    """A map as rows of finite positive factors, all rows as long (else one line); ``factors``
    may be anything (what a file or a caller gave)."""
    try:
        rows = tuple(tuple(float(v) for v in row) for row in factors)
    except (TypeError, ValueError):
        raise BadInput(None, f"{what}: must be rows of numbers, got {factors!r}") from None
    if not rows or not rows[0] or len({len(r) for r in rows}) != 1:
        raise BadInput(None, f"{what}: must be R rows of C factors (R, C >= 1), got {factors!r}")
    if not all(math.isfinite(v) and v > 0 for r in rows for v in r):
        raise BadInput(None, f"{what}: factors must be finite and positive, got {factors!r}")
    return rows


def region_of(xy: np.ndarray, footprint: tuple[float, float], shape: tuple[int, int]
              ) -> np.ndarray:
    """The (row, column) region index (K, 2) of points (K, 2) in m on the footprint (L, W);
    points beyond an edge fall into the edge's region."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    rows, cols = shape
    length, width = footprint
    col = np.clip(np.floor(xy[:, 0] / (length / cols)), 0, cols - 1).astype(int)
    row = np.clip(np.floor(xy[:, 1] / (width / rows)), 0, rows - 1).astype(int)
    return np.stack([row, col], axis=1)


def region_centres(footprint: tuple[float, float], shape: tuple[int, int]) -> np.ndarray:
    """The centres (R, C, 2) of the regions, m."""
    rows, cols = shape
    length, width = footprint
    x = (np.arange(cols) + 0.5) * length / cols
    y = (np.arange(rows) + 0.5) * width / rows
    return np.stack(np.meshgrid(x, y, indexing="xy"), axis=-1)


def region_bounds(footprint: tuple[float, float], shape: tuple[int, int], row: int, col: int
                  ) -> tuple[float, float, float, float]:
    """(x0, x1, y0, y1) of one region, m."""
    rows, cols = shape
    length, width = footprint
    return (col * length / cols, (col + 1) * length / cols, row * width / rows,
            (row + 1) * width / rows)


def mass_factors(rest_xy: np.ndarray, footprint: tuple[float, float],
                 factors: tuple[tuple[float, ...], ...]) -> np.ndarray:
    """Each mass's factor (N,) from its rest (x, y) (N, 2) in m."""
    table = np.asarray(factors, dtype=float)
    idx = region_of(rest_xy, footprint, table.shape)
    return table[idx[:, 0], idx[:, 1]]


def finest_grid(places: np.ndarray, footprint: tuple[float, float]) -> tuple[int, int]:
    """The finest grid (rows, columns) whose every region holds a press place (K, 2), m,
    in its middle (:data:`MIDDLE`): a map as fine as the presses can tell. The most regions
    win, then the squarest; (1, 1) when no finer grid is covered."""
    places = np.asarray(places, dtype=float).reshape(-1, 2)
    best = (1, 1)
    for rows in range(1, MAX_REGIONS + 1):
        for cols in range(1, MAX_REGIONS // rows + 1):
            if (rows * cols, -abs(rows - cols)) > (best[0] * best[1], -abs(best[0] - best[1])) \
                    and _covered(places, footprint, (rows, cols)):
                best = (rows, cols)
    return best


def _covered(places: np.ndarray, footprint: tuple[float, float], shape: tuple[int, int]
             ) -> bool:
    """Whether every region of ``shape`` holds a place in its middle."""
    size = np.asarray(footprint) / np.asarray(shape[::-1])          # (x, y) size of a region
    cell = np.floor(places / size)
    middle = np.all(np.abs(places - (cell + 0.5) * size) <= MIDDLE * size, axis=1)
    inside = np.all((cell >= 0) & (cell < np.asarray(shape[::-1])), axis=1) & middle
    held = {(int(c[1]), int(c[0])) for c in cell[inside]}
    return len(held) == shape[0] * shape[1]

"""The twin's curved phantoms: a dome over the footprint, or any mould's surface, as the top
its lattice is stretched to (:class:`sim.twin.phantom.Phantom`).

``dome:HEIGHT`` is a spherical cap HEIGHT mm high over the block: the sphere meets the table's
block at the footprint's corners and rises HEIGHT mm above it at the centre, on the twin's
32 mm block. A file is any watertight surface whose base stands flat on the table (its lowest
z): its footprint is its extent in x and y, and the lattice's columns reach its top surface
(a column thinner than :data:`MIN_COLUMN_M`, at a mould's very edge, is that tall). The shape's
own frame is kept: it is the phantom frame sync registers the markers to, and the twin writes
the dome in it (the footprint on [0, L] x [0, W], the block's rim at z = 0, its base at
z = -32 mm), as a mould's CAD file would be.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.errors import BadInput
from data_schema.shape import Shape, heightfield_solid, read_shape, shape_from_mesh

DOME = "dome:"
DOME_MM = (1.0, 60.0)       # a dome's height: a bump to a half sphere on the default block
MIN_COLUMN_M = 1e-3         # the lattice's thinnest column
GRID = 41                   # a dome's surface: GRID x GRID vertices over the footprint


@dataclass(frozen=True)
class TwinShape:
    """A shape and where the twin's frame sits in it: the footprint's centre on the table."""

    shape: Shape
    origin: np.ndarray        # (3,) the twin frame's origin in the shape's frame (m)
    text: str                 # what --shape said

    @property
    def footprint(self) -> tuple[float, float]:
        """The footprint (L, W) in m: the shape's extent in x and y."""
        ext = self.shape.vertices.max(axis=0) - self.shape.vertices.min(axis=0)
        return float(ext[0]), float(ext[1])

    def top(self, xy: np.ndarray) -> np.ndarray:
        """The top surface's height above the table (P,) over twin-frame points (P, 2)."""
        z = self.shape.height(np.asarray(xy) + self.origin[:2]) - self.origin[2]
        if not np.isfinite(z).all():
            raise BadInput("--shape", f"{self.text}: its top does not cover the footprint "
                                      "(no surface above a part of it)")
        return np.maximum(z, MIN_COLUMN_M)

    def to_shape(self) -> np.ndarray:
        """(4, 4) twin frame -> the shape's frame (a translation)."""
        out = np.eye(4)
        out[:3, 3] = self.origin
        return out


def check_one_silicone(shape: object, inclusions: tuple, layer: object) -> None:
    """Refuse a curved twin with other silicones: its inclusions and layers are laid out
    under a flat top."""
    if shape is not None and (inclusions or layer is not None):
        raise BadInput("--shape", "a curved twin has one silicone: inclusions and a layer "
                                  "are laid out under a flat top")


def parse_shape(text: str, size: tuple[float, float, float]) -> TwinShape:
    """``dome:HEIGHT`` (mm) over a block of ``size`` (m), or a surface file (mm)."""
    if text.startswith(DOME):
        try:
            height = float(text[len(DOME):]) * 1e-3
        except ValueError:
            raise BadInput("--shape", f"{text!r}: a dome is dome:HEIGHT in mm") from None
        if not DOME_MM[0] <= height * 1e3 <= DOME_MM[1]:
            raise BadInput("--shape", f"{text!r}: a dome's height must be in "
                                      f"[{DOME_MM[0]:g}, {DOME_MM[1]:g}] mm")
        return dome(size, height, text)
    shape = read_shape(Path(text))
    lo, hi = shape.vertices.min(axis=0), shape.vertices.max(axis=0)
    return TwinShape(shape, np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]]), text)


def dome(size: tuple[float, float, float], height: float, text: str) -> TwinShape:
    """A spherical cap ``height`` (m) high over a block of ``size`` (m), in the frame the module
    docstring gives."""
    length, width, thickness = size
    half = np.hypot(length, width) / 2
    radius = (half ** 2 + height ** 2) / (2 * height)

    def cap(xy: np.ndarray) -> np.ndarray:
        r2 = (xy[:, 0] - length / 2) ** 2 + (xy[:, 1] - width / 2) ** 2
        return np.sqrt(np.maximum(radius ** 2 - r2, 0.0)) - (radius - height)

    mesh = heightfield_solid(np.linspace(0, length, GRID), np.linspace(0, width, GRID), cap,
                             -thickness)
    return TwinShape(shape_from_mesh(mesh, text), np.array([length / 2, width / 2, -thickness]),
                     text)

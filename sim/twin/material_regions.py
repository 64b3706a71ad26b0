"""Parts of the twin's block made of another silicone: inclusions (a lump) and a top layer.

A palpation trainer is a soft block with a stiffer inclusion (a tumour), or a stiffer layer
under a soft skin. The twin places

* an :class:`Inclusion`: a sphere whose centre lies at ``(x, y)`` on the block's footprint
  (``[0, L] x [0, W]``, the origin at the block's corner of smallest x and y: the corner the
  states' phantom frame puts at its origin) and ``depth`` below the rest surface (the depth of
  its *centre*), with a ``radius``; a sphere that reaches past the block's faces is cut by
  them;
* a :class:`Layer`: the slab from the rest surface down to ``thickness``.

Each is made of the block's silicone ``ratio`` times as stiff (:data:`RATIO_RANGE`: a ratio
below 1 is softer). Where an inclusion lies in the layer, the inclusion's silicone replaces
the layer's; two inclusions may not overlap.

**How the lattice carries them.** A region's boundary does not follow the lattice's springs
(5 mm across, 8 mm through the thickness), so each spring is scaled by what it passes through,
as springs in series along it: a spring of stiffness ``k`` whose length lies a share ``s_i`` in
silicone of ratio ``r_i`` (the rest in the block's) has ::

    1 / k_eff = (1 - sum s_i) / k + sum s_i / (r_i k)

(:func:`series_scale`), the shares measured exactly on the straight spring (the intervals of
its length inside a sphere or below a plane). A spring that lies in one node layer
(horizontal) crosses no depth, and a layer's boundary may lie on its node layer exactly; such a
spring stands for the silicone from half a node spacing above it to half below (within the
block), side by side, in parallel: its ``k_eff`` is the mean of the series rule over that band
of heights (a :data:`BAND_POINTS`-point midpoint rule). So the top surface's springs under a
3 mm layer are three quarters of the layer's silicone, and a thinner layer fades smoothly to
none. The whole spring energy (its strain stiffening too) is scaled: the inclusion is the same
kind of silicone, stiffer.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from core.errors import BadInput

RATIO_RANGE = (0.3, 10.0)          # a region's silicone, times the block's stiffness
RADIUS_RANGE_M = (0.002, 0.100)    # an inclusion's radius: from 2 mm (every point of the
#                                    lattice lies within 1.6 mm of a spring) to the block's size
BAND_POINTS = 16                   # heights a horizontal spring's band is averaged over
INCLUSION_FORM = "X,Y,DEPTH,RADIUS,RATIO"
LAYER_FORM = "THICKNESS,RATIO"


@dataclass(frozen=True)
class Inclusion:
    """A sphere of another silicone (metres): centre at (``x``, ``y``) on the footprint and
    ``depth`` below the rest surface, ``radius``, stiffness ``ratio`` to the block's."""

    x: float
    y: float
    depth: float
    radius: float
    ratio: float

    def __post_init__(self) -> None:
        _finite("--inclusion", x=self.x, y=self.y, depth=self.depth, radius=self.radius,
                ratio=self.ratio)
        _check_ratio("--inclusion", self.ratio)
        lo, hi = RADIUS_RANGE_M
        if not lo <= self.radius <= hi:
            raise BadInput("--inclusion", f"radius {self.radius * 1e3:g} mm: must be in "
                           f"[{lo * 1e3:g}, {hi * 1e3:g}] mm")

    def centre(self, size: Sequence[float]) -> np.ndarray:
        """The centre in the twin's phantom frame (the block's bottom centre, z up) of a block
        of ``size`` (L, W, thickness)."""
        return np.array([self.x - size[0] / 2, self.y - size[1] / 2, size[2] - self.depth])

    def describe(self) -> str:
        """E.g. ``r 12 mm at (50, 50) mm, 10 mm deep, 3x``."""
        return (f"r {self.radius * 1e3:g} mm at ({self.x * 1e3:g}, {self.y * 1e3:g}) mm, "
                f"{self.depth * 1e3:g} mm deep, {self.ratio:g}x")


@dataclass(frozen=True)
class Layer:
    """The top ``thickness`` (m) of the block, of stiffness ``ratio`` to the block's."""

    thickness: float
    ratio: float

    def __post_init__(self) -> None:
        _finite("--layer", thickness=self.thickness, ratio=self.ratio)
        _check_ratio("--layer", self.ratio)
        if self.thickness <= 0.0:
            raise BadInput("--layer", f"thickness {self.thickness * 1e3:g} mm: must be > 0")

    def describe(self) -> str:
        """E.g. ``top 3 mm, 0.5x``."""
        return f"top {self.thickness * 1e3:g} mm, {self.ratio:g}x"


def parse_inclusion(text: str) -> Inclusion:
    """``--inclusion X,Y,DEPTH,RADIUS,RATIO`` (mm, and the ratio) as an :class:`Inclusion`."""
    x, y, depth, radius, ratio = _numbers("--inclusion", text, INCLUSION_FORM, 5,
                                          "e.g. 50,50,10,12,3")
    return Inclusion(x / 1e3, y / 1e3, depth / 1e3, radius / 1e3, ratio)


def parse_layer(text: str) -> Layer:
    """``--layer THICKNESS,RATIO`` (mm, and the ratio) as a :class:`Layer`."""
    thickness, ratio = _numbers("--layer", text, LAYER_FORM, 2, "e.g. 3,0.5")
    return Layer(thickness / 1e3, ratio)


def check_regions(inclusions: Sequence[Inclusion], layer: Layer | None,
                  size: Sequence[float]) -> None:
    """Refuse regions a block of ``size`` (L, W, thickness, m) cannot hold: an inclusion whose
    centre is not inside it, two inclusions that overlap, a layer not thinner than it."""
    length, width, thick = size
    for k, inc in enumerate(inclusions):
        inside = 0.0 < inc.x < length and 0.0 < inc.y < width and 0.0 < inc.depth < thick
        if not inside:
            raise BadInput("--inclusion", f"{inc.describe()}: its centre is outside the "
                           f"{length * 1e3:g} x {width * 1e3:g} x {thick * 1e3:g} mm block "
                           f"(x in (0, {length * 1e3:g}), y in (0, {width * 1e3:g}), depth in "
                           f"(0, {thick * 1e3:g}) mm)")
        for j, other in enumerate(inclusions[:k]):
            gap = math.dist((inc.x, inc.y, inc.depth), (other.x, other.y, other.depth))
            if gap < inc.radius + other.radius:
                raise BadInput("--inclusion", f"inclusions {j} and {k} overlap ({other.describe()}"
                                              f"; {inc.describe()})")
    if layer is not None and layer.thickness >= thick:
        raise BadInput("--layer", f"thickness {layer.thickness * 1e3:g} mm: must be thinner than "
                                  f"the {thick * 1e3:g} mm block")


def spring_scale(p0: np.ndarray, p1: np.ndarray, inclusions: Sequence[Inclusion],
                 layer: Layer | None, size: Sequence[float], band: float) -> np.ndarray:
    """(E,) factor on each spring's stiffness, the springs from ``p0`` to ``p1`` (E, 3) at rest
    in the twin's phantom frame of a block of ``size``; a horizontal spring averaged over the
    ``band`` (m) of heights it stands for (see the module docstring). 1 everywhere when there
    are no regions."""
    scale = np.ones(len(p0))
    if not inclusions and layer is None:
        return scale
    flat = np.abs(p1[:, 2] - p0[:, 2]) <= 1e-9 * size[2]
    scale[~flat] = series_scale(p0[~flat], p1[~flat], inclusions, layer, size)
    z = p0[flat, 2]
    lo, hi = np.maximum(z - band / 2, 0.0), np.minimum(z + band / 2, size[2])
    heights = lo[:, None] + (hi - lo)[:, None] * (np.arange(BAND_POINTS) + 0.5) / BAND_POINTS
    lift = np.zeros(heights.shape + (3,))
    lift[..., 2] = heights - z[:, None]                                  # (F, B, 3)
    a = (p0[flat][:, None] + lift).reshape(-1, 3)
    b = (p1[flat][:, None] + lift).reshape(-1, 3)
    scale[flat] = series_scale(a, b, inclusions, layer, size).reshape(heights.shape).mean(axis=1)
    return scale


def series_scale(p0: np.ndarray, p1: np.ndarray, inclusions: Sequence[Inclusion],
                 layer: Layer | None, size: Sequence[float]) -> np.ndarray:
    """(E,) ``k_eff / k`` of straight springs from ``p0`` to ``p1`` (E, 3): the silicones along
    each in series, ``1 / (1 + sum s_i (1 / r_i - 1))`` (exactly 1 for a ratio of 1)."""
    compliance = np.ones(len(p0))
    pieces = []
    for inc in inclusions:
        t0, t1 = sphere_interval(p0, p1, inc.centre(size), inc.radius)
        compliance += (t1 - t0) * (1.0 / inc.ratio - 1.0)
        pieces.append((t0, t1))
    if layer is not None:
        t0, t1 = below_interval(p0, p1, size[2] - layer.thickness)
        share = t1 - t0 - sum(np.maximum(0.0, np.minimum(t1, e) - np.maximum(t0, s))
                              for s, e in pieces)                     # the inclusions' part
        compliance += share * (1.0 / layer.ratio - 1.0)
    return 1.0 / compliance


def sphere_interval(p0: np.ndarray, p1: np.ndarray, centre: np.ndarray,
                    radius: float) -> tuple[np.ndarray, np.ndarray]:
    """(t0, t1) (E,) each: the part ``p0 + t (p1 - p0)``, ``t0 <= t <= t1`` in [0, 1], of each
    segment inside the sphere (``t0 == t1`` where it misses)."""
    d, f = p1 - p0, p0 - centre
    a = (d * d).sum(axis=1)
    b = (f * d).sum(axis=1)
    root = np.sqrt(np.maximum(b * b - a * ((f * f).sum(axis=1) - radius**2), 0.0))
    t0 = np.clip((-b - root) / a, 0.0, 1.0)
    t1 = np.clip((-b + root) / a, 0.0, 1.0)
    return t0, np.maximum(t0, t1)


def below_interval(p0: np.ndarray, p1: np.ndarray, z_floor: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(t0, t1) (E,) each: the part of each segment at or above height ``z_floor`` (the slab
    from there to the top), as :func:`sphere_interval`."""
    z0, dz = p0[:, 2], p1[:, 2] - p0[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        cross = np.where(dz != 0.0, (z_floor - z0) / np.where(dz != 0.0, dz, 1.0), 0.0)
    level = np.where(z0 >= z_floor, 0.0, 1.0)                # a horizontal segment: all or none
    t0 = np.clip(np.where(dz > 0, cross, np.where(dz < 0, 0.0, level)), 0.0, 1.0)
    t1 = np.clip(np.where(dz < 0, cross, 1.0), 0.0, 1.0)
    return t0, np.maximum(t0, t1)


def _numbers(option: str, text: str, form: str, count: int, example: str) -> list[float]:
    """``count`` comma-separated numbers of ``text``, or BadInput naming ``option``."""
    parts = [p.strip() for p in str(text).split(",")]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if len(values) != count:
        raise BadInput(option, f"{text!r}: must be {form} ({example})")
    return values


def _finite(option: str, **values: float) -> None:
    for name, v in values.items():
        if not math.isfinite(v):
            raise BadInput(option, f"{name} {v}: not a finite number")


def _check_ratio(option: str, ratio: float) -> None:
    lo, hi = RATIO_RANGE
    if not lo <= ratio <= hi:
        raise BadInput(option, f"ratio {ratio:g}: must be in [{lo:g}, {hi:g}] (the silicone's "
                               "stiffness over the block's)")

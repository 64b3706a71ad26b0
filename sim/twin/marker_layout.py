"""Where the twin's phantom markers sit on the block's top, and the lattice that carries them.

Two layouts (``pipeline synth --markers``):

* a grid ``RxC`` (``R`` rows of ``C`` markers, ``pitch`` apart, centred on the block): rows
  run along the block's +x, stacked along +y, and the markers are named row-major (``P00`` is
  the row at the smallest y, its marker at the smallest x), as extract's frame reads a grid;
* ``scattered:N``: ``N`` markers at random lattice nodes (the seed's own stream), at least
  ``min_spacing`` apart and ``margin`` inside the block's edges. The first two (``P00``,
  ``P01``) lie on one line along +x, at least half the usable length apart: the in-plane axis
  a lab would declare (session.toml ``[phantom] x_axis``), ``P00`` its anchor.

The lattice's in-plane spacing is ``SPACING_M`` unless a grid asks for a finer one: a grid's
pitch spans at least ``PITCH_SPACINGS`` spacings, so that a press between four markers stays
two spacings clear of each (:meth:`sim.twin.phantom.Phantom.candidate_locations`). The nodes
of each axis are laid from the markers outwards, the block's edges closing the outermost cells
(between half and one and a half spacings wide) when the footprint is not a whole number of
spacings.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from core.errors import BadInput

SPACING_M = 0.005          # the lattice's in-plane spacing unless a grid needs a finer one
PITCH_SPACINGS = 4         # a grid's pitch spans at least this many lattice spacings
MIN_PITCH_M = 0.010        # finer grids would need a lattice finer than 2.5 mm
MARGIN_M = 0.010           # every marker this far inside the block's edges
MIN_SPACING_M = 0.010      # scattered markers at least this far apart
SIZE_RANGE_M = (0.040, 0.300)   # footprint sides the lattice can carry in seconds
LAYOUT_STREAM = 8          # the scattered draw: this child of the twin seed's SeedSequence


@dataclass(frozen=True)
class MarkerLayout:
    """A grid of ``rows`` x ``cols`` markers ``pitch`` apart, or (``scattered`` > 0) that many
    markers at random nodes drawn from ``seed`` (metres)."""

    rows: int = 5
    cols: int = 5
    pitch: float = 0.020
    scattered: int = 0
    seed: int = 0
    min_spacing: float = MIN_SPACING_M
    margin: float = MARGIN_M

    @property
    def count(self) -> int:
        """How many markers the layout places."""
        return self.scattered or self.rows * self.cols

    @property
    def names(self) -> tuple[str, ...]:
        """``P00``, ``P01``, ... (row-major for a grid)."""
        return marker_names(self.count)

    def describe(self) -> str:
        """The layout in words, e.g. ``6 x 6 markers 12 mm apart`` or ``20 scattered markers``."""
        if self.scattered:
            return f"{self.scattered} scattered markers"
        return f"{self.rows} x {self.cols} markers {self.pitch * 1e3:g} mm apart"

    def spacing(self) -> float:
        """The lattice's in-plane spacing (m): ``SPACING_M``, or the pitch over a whole number
        (at least ``PITCH_SPACINGS``) of spacings no wider than it."""
        if self.scattered:
            return SPACING_M
        return self.pitch / max(PITCH_SPACINGS, math.ceil(self.pitch / SPACING_M - 1e-9))


def marker_names(n: int) -> tuple[str, ...]:
    """The twin's names of ``n`` phantom markers."""
    return tuple(f"P{k:02d}" for k in range(n))


def layout_text(layout: MarkerLayout) -> str:
    """``layout`` as ``--markers`` writes it: ``RxC`` or ``scattered:N``."""
    return f"scattered:{layout.scattered}" if layout.scattered else \
        f"{layout.rows}x{layout.cols}"


def size_text(size: tuple[float, ...]) -> str:
    """A footprint (L, W, ...) in m as ``--size`` writes it: ``LxW`` in mm."""
    return f"{size[0] * 1e3:g}x{size[1] * 1e3:g}"


def parse_layout(text: str, pitch_mm: float = MarkerLayout.pitch * 1e3,
                 seed: int = 0) -> MarkerLayout:
    """``--markers`` (``RxC`` or ``scattered:N``) and ``--marker-pitch`` as a layout."""
    grid = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    scattered = re.fullmatch(r"\s*scattered\s*:\s*(\d+)\s*", text)
    if grid:
        rows, cols = int(grid[1]), int(grid[2])
        if rows < 2 or cols < 2:
            raise BadInput("--markers", f"{text!r}: a grid needs at least 2 rows of 2 markers")
        if not (math.isfinite(pitch_mm) and pitch_mm >= MIN_PITCH_M * 1e3):
            raise BadInput("--marker-pitch", f"{pitch_mm:g} mm: must be at least "
                           f"{MIN_PITCH_M * 1e3:g} mm (the lattice would be finer than "
                           f"{MIN_PITCH_M / PITCH_SPACINGS * 1e3:g} mm)")
        return MarkerLayout(rows=rows, cols=cols, pitch=pitch_mm / 1e3, seed=seed)
    if scattered:
        n = int(scattered[1])
        if n < 4:
            raise BadInput("--markers", f"{text!r}: a phantom needs at least 4 markers")
        return MarkerLayout(scattered=n, seed=seed)
    raise BadInput("--markers", f"{text!r}: must be a grid RxC (e.g. 6x6) or scattered:N "
                                "(e.g. scattered:20)")


def parse_size(text: str) -> tuple[float, float]:
    """``--size LxW`` (mm) as the footprint (m), each side within ``SIZE_RANGE_M``."""
    m = re.fullmatch(r"\s*(\d+(?:\.\d*)?)\s*[xX]\s*(\d+(?:\.\d*)?)\s*", text)
    if not m:
        raise BadInput("--size", f"{text!r}: must be LxW in mm (e.g. 150x80)")
    size = (float(m[1]) / 1e3, float(m[2]) / 1e3)
    lo, hi = SIZE_RANGE_M
    if not all(lo <= s <= hi for s in size):
        raise BadInput("--size", f"{text!r}: each side must be {lo * 1e3:g} to {hi * 1e3:g} mm")
    return size


def lattice_axes(size: tuple[float, float], layout: MarkerLayout
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The lattice's node coordinates along x and y (m, centred on the block), laid from the
    grid's first column and row (a scattered layout: from the centre) outwards."""
    h = layout.spacing()
    if layout.scattered:
        return _axis(size[0], h, 0.0), _axis(size[1], h, 0.0)
    _check_grid_fits(size, layout)
    return (_axis(size[0], h, -(layout.cols - 1) * layout.pitch / 2),
            _axis(size[1], h, -(layout.rows - 1) * layout.pitch / 2))


def _axis(length: float, h: float, anchor: float) -> np.ndarray:
    """Nodes ``anchor + k h`` at least ``h / 2`` inside (-length/2, length/2), and its ends."""
    half = length / 2
    steps = length / h
    if abs(steps - round(steps)) < 1e-9 and abs((anchor + half) / h
                                                 - round((anchor + half) / h)) < 1e-9:
        return np.linspace(-half, half, int(round(steps)) + 1)
    lo = math.ceil((-half + h / 2 - anchor) / h - 1e-9)
    hi = math.floor((half - h / 2 - anchor) / h + 1e-9)
    return np.concatenate([[-half], anchor + h * np.arange(lo, hi + 1), [half]])


def _check_grid_fits(size: tuple[float, float], layout: MarkerLayout) -> None:
    span = ((layout.cols - 1) * layout.pitch, (layout.rows - 1) * layout.pitch)
    if any(s > side - 2 * layout.margin + 1e-9 for s, side in zip(span, size, strict=True)):
        raise BadInput("--markers", f"a {layout.rows}x{layout.cols} grid {layout.pitch * 1e3:g}"
                       f" mm apart spans {span[0] * 1e3:g} x {span[1] * 1e3:g} mm: more than "
                       f"the {size[0] * 1e3:g} x {size[1] * 1e3:g} mm block leaves "
                       f"{layout.margin * 1e3:g} mm inside its edges")


def marker_nodes(layout: MarkerLayout, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """(M, 2) top-lattice indices (i along x, j along y) of the markers, in name order."""
    if layout.scattered:
        return _scattered_nodes(layout, xs, ys)
    cols = [_node(xs, (c - (layout.cols - 1) / 2) * layout.pitch) for c in range(layout.cols)]
    rows = [_node(ys, (r - (layout.rows - 1) / 2) * layout.pitch) for r in range(layout.rows)]
    return np.array([(i, j) for j in rows for i in cols])


def _node(axis: np.ndarray, at: float) -> int:
    """The index of the node at ``at`` (a grid's markers lie on nodes by construction)."""
    i = int(np.argmin(np.abs(axis - at)))
    if abs(axis[i] - at) > 1e-9:
        raise AssertionError(f"no lattice node at {at} m")   # lattice_axes guarantees one
    return i


def _scattered_nodes(layout: MarkerLayout, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """Random nodes ``min_spacing`` apart, ``margin`` inside the edges; the first two on one
    row, the second at larger x, at least half the usable length from the first."""
    rng = np.random.default_rng(np.random.SeedSequence(layout.seed,
                                                       spawn_key=(LAYOUT_STREAM,)))
    inside_x = np.flatnonzero(np.abs(xs) <= xs[-1] - layout.margin + 1e-9)
    inside_y = np.flatnonzero(np.abs(ys) <= ys[-1] - layout.margin + 1e-9)
    reach = xs[inside_x[-1]] - xs[inside_x[0]]
    pairs = [(a, b) for a in inside_x for b in inside_x if xs[b] - xs[a] >= reach / 2 - 1e-9]
    a, b = pairs[rng.integers(len(pairs))]
    j = int(rng.choice(inside_y))
    chosen = [(int(a), j), (int(b), j)]
    nodes = np.array([(i, jj) for i in inside_x for jj in inside_y])
    for k in rng.permutation(len(nodes)):
        if len(chosen) == layout.count:
            break
        i, jj = nodes[k]
        if all(math.hypot(xs[i] - xs[p], ys[jj] - ys[q]) >= layout.min_spacing - 1e-9
               for p, q in chosen):
            chosen.append((int(i), int(jj)))
    if len(chosen) < layout.count:
        raise BadInput("--markers", f"only {len(chosen)} of {layout.count} scattered markers "
                       f"fit {layout.min_spacing * 1e3:g} mm apart and {layout.margin * 1e3:g}"
                       f" mm inside a {(xs[-1] - xs[0]) * 1e3:g} x {(ys[-1] - ys[0]) * 1e3:g}"
                       " mm block")
    return np.array(chosen)

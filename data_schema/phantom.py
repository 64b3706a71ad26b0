"""The phantom's layout: its footprint, and how its markers fix the phantom frame.

session.toml's optional ``[phantom]`` table (lengths in mm, as labs measure them)::

    [phantom]
    size_mm = [150.0, 80.0]      # the footprint, L along +x by W; default 100 x 100
    x_axis = ["P03", "P11"]      # +x runs from the first marker to the second (in the rest
                                 # plane); default: along the rows of the marker grid
    rows = 4                     # the markers, listed row-major, form this many rows
                                 # (default: a square grid when their number is a square)
    anchor = "P00"               # with anchor_mm: this marker rests at anchor_mm in the
    anchor_mm = [10.0, 12.5]     # footprint; default: the markers' centroid at its centre
    interior = "interior.nii.gz" # what lies inside, with [phantom.labels] (and a CT's
                                 # [phantom.intensities]): read by fit-solid
                                 # (data_schema/interior.py), not by the frame
    shape = "mould.stl"          # a curved phantom's surface, mm, in its own frame (+z out at
                                 # the top): data_schema/shape.py; the frame becomes its frame
    marker_diameter_mm = 3.0     # with a shape: the markers' centres rest half of it off the
                                 # surface (default 3 mm)

Ingest keeps it in the MCAP's ``session`` record and sync in the synced file's ``phantom``
attribute, both as JSON in metres (:meth:`PhantomLayout.as_json`); extract builds the frame
from it (:mod:`extract.phantom_frame`): rest surface at z = 0, +z out of the phantom, the
footprint on [0, L] x [0, W]. With a ``shape`` the layout carries its surface (in the JSON,
:meth:`data_schema.shape.Shape.as_json`), sync registers the markers to it
(:mod:`calib.shape_registration`) and the frame is the shape's own.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from core.errors import BadInput
from core.protocol import FOOTPRINT_M
from data_schema.shape import Shape, read_shape

MIN_MARKERS = 4          # a rest plane and an in-plane axis need at least this many markers
KEYS = ("size_mm", "x_axis", "rows", "anchor", "anchor_mm", "shape", "marker_diameter_mm")
MARKER_DIAMETER_M = 3e-3   # a curved phantom's markers, unless [phantom] says otherwise
INTERIOR_KEYS = ("interior", "labels", "intensities")   # what lies inside: data_schema/interior.py


@dataclass(frozen=True)
class PhantomLayout:
    """The footprint (m) and what fixes the frame's in-plane axis and origin."""

    size_m: tuple[float, float] = FOOTPRINT_M
    x_axis: tuple[str, str] | None = None
    rows: int | None = None
    anchor: str | None = None
    anchor_m: tuple[float, float] | None = None
    shape: Shape | None = field(default=None, compare=False)   # None: a flat phantom
    marker_diameter_m: float = MARKER_DIAMETER_M

    def as_json(self) -> dict:
        """The layout as JSON-ready values in metres (a flat phantom's as before shapes)."""
        out: dict[str, Any] = {
            "size_m": list(self.size_m), "x_axis": None if self.x_axis is None else
            list(self.x_axis), "rows": self.rows, "anchor": self.anchor,
            "anchor_m": None if self.anchor_m is None else list(self.anchor_m)}
        if self.shape is not None:
            out.update(shape=self.shape.as_json(), marker_diameter_m=self.marker_diameter_m)
        return out

    def along_x(self, rest: np.ndarray, names: list[str]) -> tuple[np.ndarray, str]:
        """Vectors (K, 3) the layout says run along +x, among the markers' rest positions
        (N, 3): ``x_axis``'s first marker to its second, or each row's first marker to its
        last (``rows`` rows listed row-major, or a square grid); and what they are, in words.
        Refused where the markers form no grid and no ``x_axis`` is named."""
        if self.x_axis is not None:
            a, b = (names.index(m) for m in self.x_axis)
            return (rest[b] - rest[a])[None], f"x_axis {self.x_axis[0]} -> {self.x_axis[1]}"
        rows = self.rows or math.isqrt(len(rest))
        if rows < 2 or len(rest) % rows or (self.rows is None and rows * rows != len(rest)):
            raise BadInput(None, f"{len(rest)} phantom markers form no square grid and the "
                                 "layout names no x_axis or rows: no in-plane axis")
        grid = rest.reshape(rows, -1, 3)
        return grid[:, -1] - grid[:, 0], "the marker grid's rows"

    def origin(self, rest: np.ndarray, names: list[str]) -> tuple[np.ndarray, tuple[float, float]]:
        """The point (3,) that fixes the frame's origin and where on the footprint it rests:
        the anchor marker at ``anchor_m``, or the seen markers' centroid at the centre (of
        [0, L] x [0, W], or of a shape's extent in its own frame)."""
        if self.anchor is not None:
            if self.anchor_m is None:
                raise BadInput(None, f"anchor marker {self.anchor} comes without anchor_m")
            at = rest[names.index(self.anchor)]
            if not np.isfinite(at).all():
                raise BadInput(None, f"anchor marker {self.anchor} is never seen at rest")
            return at, self.anchor_m
        centre = rest[np.isfinite(rest).all(axis=1)].mean(axis=0)
        if self.shape is None:
            return centre, (self.size_m[0] / 2, self.size_m[1] / 2)
        lo, hi = self.shape.vertices.min(axis=0), self.shape.vertices.max(axis=0)
        return centre, ((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2)

    @classmethod
    def from_json(cls, d: dict | None) -> PhantomLayout:
        """Back from :meth:`as_json`; ``None`` (a file with no layout: a synced file of version
        1.2) is the default."""
        if d is None:
            return cls()
        shape = d.get("shape")
        return cls(size_m=tuple(d["size_m"]), x_axis=_pair(d.get("x_axis")),
                   rows=d.get("rows"), anchor=d.get("anchor"), anchor_m=_pair(d.get("anchor_m")),
                   shape=None if shape is None else Shape.from_json(shape),
                   marker_diameter_m=d.get("marker_diameter_m", MARKER_DIAMETER_M))


def read_layout(path: Path, t: dict | None, markers: list[str]) -> PhantomLayout:
    """session.toml's ``[phantom]`` table (``None``: absent), checked against the phantom's
    markers; anything a frame cannot be built from is refused in one line naming ``path``."""
    if len(markers) < MIN_MARKERS:
        raise BadInput(path, f"mocap.phantom_markers names {len(markers)} marker(s): a phantom "
                             f"needs at least {MIN_MARKERS} (a rest plane and an in-plane axis)")
    t = {} if t is None else t
    unknown = sorted(set(t) - set(KEYS) - set(INTERIOR_KEYS))
    if unknown:
        raise BadInput(path, f"[phantom] has unknown key(s) {unknown}; it takes {', '.join(KEYS)}")
    size = _mm_pair(path, t, "size_mm", positive=True)
    layout = PhantomLayout(
        size_m=FOOTPRINT_M if size is None else size,
        x_axis=_marker_pair(path, t.get("x_axis"), markers),
        rows=_rows(path, t.get("rows"), len(markers)),
        anchor=_anchor(path, t, markers), anchor_m=_mm_pair(path, t, "anchor_mm"),
        shape=_shape(path, t.get("shape")), marker_diameter_m=_diameter(path, t))
    if layout.x_axis is None and layout.rows is None and math.isqrt(len(markers)) ** 2 != len(
            markers):
        raise BadInput(path, f"{len(markers)} phantom markers form no square grid: say which "
                             "way +x runs ([phantom] x_axis = two markers, or rows = R for a "
                             "grid listed row-major)")
    return layout


def phantom_table(folder: str | Path) -> tuple[Path, dict]:
    """A session folder's ``session.toml`` and its ``[phantom]`` table (empty without one)."""
    toml = Path(folder) / "session.toml"
    try:
        raw = tomllib.loads(toml.read_text())
    except (OSError, tomllib.TOMLDecodeError) as e:
        raise BadInput(toml, f"unreadable session.toml ({e})") from None
    return toml, raw.get("phantom") or {}


def session_shape(folder: str | Path) -> Shape | None:
    """The shape a session folder's ``session.toml`` names (None: a flat phantom)."""
    toml, phantom = phantom_table(folder)
    return _shape(toml, phantom.get("shape"))


def _shape(path: Path, v: object) -> Shape | None:
    """``shape``: a surface file beside session.toml (or an absolute path), read and checked."""
    if v is None:
        return None
    if not isinstance(v, str) or not v:
        raise BadInput(path, f"phantom.shape must name a surface file, got {v!r}")
    return read_shape(path.parent / v)


def _diameter(path: Path, t: dict) -> float:
    """``marker_diameter_mm``: a positive length up to 30 mm (m); the default without it."""
    v = t.get("marker_diameter_mm")
    if v is None:
        return MARKER_DIAMETER_M
    if isinstance(v, bool) or not isinstance(v, int | float) or not 0 < v <= 30:
        raise BadInput(path, f"phantom.marker_diameter_mm must be a length in (0, 30] mm, "
                             f"got {v!r}")
    return float(v) / 1000.0


def _pair(v: list | None) -> tuple | None:
    return None if v is None else tuple(v)


def _mm_pair(path: Path, t: dict, key: str, positive: bool = False) -> tuple[float, float] | None:
    """Two finite lengths in mm (``positive``: > 0) as metres; None when absent."""
    v = t.get(key)
    if v is None:
        return None
    ok = (isinstance(v, list) and len(v) == 2
          and all(isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)
                  and (x > 0 or not positive) for x in v))
    if not ok:
        what = "two positive lengths" if positive else "two finite lengths"
        raise BadInput(path, f"phantom.{key} must be {what} in mm, got {v!r}")
    return (v[0] / 1000.0, v[1] / 1000.0)


def _marker_pair(path: Path, v: object, markers: list[str]) -> tuple[str, str] | None:
    """``x_axis``: two distinct phantom markers, or None."""
    if v is None:
        return None
    if not (isinstance(v, list) and len(v) == 2 and all(isinstance(x, str) for x in v)
            and v[0] != v[1]):
        raise BadInput(path, f"phantom.x_axis must name two different markers, got {v!r}")
    missing = [x for x in v if x not in markers]
    if missing:
        raise BadInput(path, f"phantom.x_axis names {missing[0]!r}, not a phantom marker")
    return (v[0], v[1])


def _rows(path: Path, v: object, n: int) -> int | None:
    """``rows``: a whole number >= 2 of rows that divides the markers into equal rows."""
    if v is None:
        return None
    if type(v) is not int or v < 2 or n % v or n // v < 2:
        raise BadInput(path, f"phantom.rows must split the {n} markers into equal rows of at "
                             f"least 2, got {v!r}")
    return v


def _anchor(path: Path, t: dict, markers: list[str]) -> str | None:
    """``anchor`` names a phantom marker, and comes with ``anchor_mm``."""
    v = t.get("anchor")
    if (v is None) != (t.get("anchor_mm") is None):
        raise BadInput(path, "phantom.anchor and phantom.anchor_mm come together")
    if v is not None and v not in markers:
        raise BadInput(path, f"phantom.anchor = {v!r} is not a phantom marker")
    return v

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

Ingest keeps it in the MCAP's ``session`` record and sync in the synced file's ``phantom``
attribute, both as JSON in metres (:meth:`PhantomLayout.as_json`); extract builds the frame
from it (:mod:`extract.phantom_frame`): rest surface at z = 0, +z out of the phantom, the
footprint on [0, L] x [0, W].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from core.errors import BadInput
from core.protocol import FOOTPRINT_M

MIN_MARKERS = 4          # a rest plane and an in-plane axis need at least this many markers
KEYS = ("size_mm", "x_axis", "rows", "anchor", "anchor_mm")
INTERIOR_KEYS = ("interior", "labels", "intensities")   # what lies inside: data_schema/interior.py


@dataclass(frozen=True)
class PhantomLayout:
    """The footprint (m) and what fixes the frame's in-plane axis and origin."""

    size_m: tuple[float, float] = FOOTPRINT_M
    x_axis: tuple[str, str] | None = None
    rows: int | None = None
    anchor: str | None = None
    anchor_m: tuple[float, float] | None = None

    def as_json(self) -> dict:
        """The layout as JSON-ready values in metres."""
        return {"size_m": list(self.size_m), "x_axis": None if self.x_axis is None else
                list(self.x_axis), "rows": self.rows, "anchor": self.anchor,
                "anchor_m": None if self.anchor_m is None else list(self.anchor_m)}

    @classmethod
    def from_json(cls, d: dict | None) -> PhantomLayout:
        """Back from :meth:`as_json`; ``None`` (a file with no layout: a synced file of version
        1.2) is the default."""
        if d is None:
            return cls()
        return cls(size_m=tuple(d["size_m"]), x_axis=_pair(d.get("x_axis")),
                   rows=d.get("rows"), anchor=d.get("anchor"), anchor_m=_pair(d.get("anchor_m")))


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
        anchor=_anchor(path, t, markers), anchor_m=_mm_pair(path, t, "anchor_mm"))
    if layout.x_axis is None and layout.rows is None and math.isqrt(len(markers)) ** 2 != len(
            markers):
        raise BadInput(path, f"{len(markers)} phantom markers form no square grid: say which "
                             "way +x runs ([phantom] x_axis = two markers, or rows = R for a "
                             "grid listed row-major)")
    return layout


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

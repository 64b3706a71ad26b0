"""A lab's marker layout for the MSM: where its markers rest, and the masses inside it.

``simulate --layout`` samples the MSM at a lab's markers (their median rest positions in the
phantom frame, which is the grid's frame), any number of them, and loads only the masses
inside the markers' bounding box, where the lab pressed. The lab states' root attributes say
the rest: ``point_names`` names the markers (then "tip"), ``footprint_m`` is the footprint
[L, W] its frame uses, which the MSM's surface is sized to (absent: the paper's 100 mm square).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from core.errors import BadInput
from data_schema.hdf5 import attr_text
from data_schema.states import check_flat_rest, point_names, validate_states
from data_schema.states import footprint as states_footprint
from sim.msm.msm import MSM, MSMParams

OUTSIDE_M = 1e-3        # m: a marker resting further outside the MSM's surface is refused


@dataclass(frozen=True)
class LabLayout:
    """A lab's markers at rest, their names and the footprint of its phantom frame."""

    points: np.ndarray                          # (P, 3) m, phantom frame, the tip left out
    names: list[str] | None                     # the P markers' names (None: not named)
    footprint: tuple[float, float] | None       # (L, W) m (None: the paper's square)

    @property
    def point_names(self) -> list[str] | None:
        """What the MSM states' ``point_names`` attribute holds: the markers, then "tip"."""
        return None if self.names is None else [*self.names, "tip"]


def read_layout(path: str | Path, curved: bool = False) -> LabLayout:
    """The layout of a lab states file (:func:`lab_layout`), its names and footprint
    (``curved``: a curved phantom's, for a solid of its shape)."""
    points = lab_layout(path, curved)
    names = point_names(path)
    if names is not None and len(names) != len(points) + 1:
        raise BadInput(path, f"point_names names {len(names)} points for {len(points)} "
                             "markers and the tip")
    return LabLayout(points, None if names is None else list(names[:-1]),
                     states_footprint(path))


def check_inside(layout: np.ndarray, params: MSMParams, source: str | Path,
                 names: list[str] | None = None) -> None:
    """Refuse (one line naming ``source``) a layout with a marker resting outside the MSM's
    surface [0, L] x [0, W] by more than :data:`OUTSIDE_M`: it would follow the edge."""
    size = np.array(params.footprint)
    out = (layout[:, :2] < -OUTSIDE_M) | (layout[:, :2] > size + OUTSIDE_M)
    bad = np.flatnonzero(out.any(axis=1))
    if len(bad):
        k = int(bad[0])
        name = names[k] if names else f"point {k}"
        x, y = layout[k, :2] * 1e3
        raise BadInput(source, f"marker {name} rests at ({x:.1f}, {y:.1f}) mm, outside the "
                               f"MSM's {size[0] * 1e3:g} x {size[1] * 1e3:g} mm surface: give "
                               "the phantom's footprint (--size LxW)")


def footprint(model: MSM, layout: np.ndarray) -> np.ndarray:
    """The masses inside the bounding box of a layout's points in the plane."""
    lo, hi = layout[:, :2].min(axis=0), layout[:, :2].max(axis=0)
    xy = model.rest[:, :2]
    return np.flatnonzero(((xy >= lo) & (xy <= hi)).all(axis=1))


def lab_layout(path: str | Path, curved: bool = False) -> np.ndarray:
    """The rest positions (P, 3) of a lab states file's surface points, phantom frame (a
    curved phantom's only where ``curved``: the MSM is a flat surface).

    Each point's median over the sequences' rest states (step 0), ignoring the instants it
    was missing; the tip (the last point, which sits at ``states/tip``) is left out.
    """
    path = Path(path)
    validate_states(path)
    with h5py.File(path, "r") as f:
        if attr_text(f.attrs["source"]) != "lab":
            raise BadInput(path, "--layout needs extracted lab states (source 'lab')")
        rest = f["states/step"][()] == 0
        points = f["states/points"][()][rest].astype(float)
        valid = f["states/valid"][()][rest]
        tips = f["states/tip"][()][rest].astype(float)
    if not np.allclose(points[:, -1], tips, atol=1e-6, equal_nan=True):
        raise BadInput(path, "its last point is not the tip: not a lab states layout")
    points = np.where(valid[..., None], points, np.nan)[:, :-1]
    seen = np.isfinite(points).all(axis=-1).any(axis=0)
    if not seen.all():
        raise BadInput(path, f"point {int(np.flatnonzero(~seen)[0])} is never seen at rest: "
                             "no layout for it")
    layout = np.nanmedian(points, axis=0)
    if not curved:
        check_flat_rest(layout, path)
    return layout

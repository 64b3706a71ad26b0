"""A lab's marker layout for the MSM: where its markers rest, and the masses inside it.

``simulate --layout`` samples the MSM at a lab's markers (their median rest positions in the
phantom frame, which is the grid's frame) and loads only the masses inside the markers'
footprint, where the lab pressed.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from core.errors import BadInput
from data_schema.hdf5 import attr_text
from data_schema.states import validate_states
from sim.msm.msm import MSM


def footprint(model: MSM, layout: np.ndarray) -> np.ndarray:
    """The masses inside the bounding box of a layout's points in the plane."""
    lo, hi = layout[:, :2].min(axis=0), layout[:, :2].max(axis=0)
    xy = model.rest[:, :2]
    return np.flatnonzero(((xy >= lo) & (xy <= hi)).all(axis=1))


def lab_layout(path: str | Path) -> np.ndarray:
    """The rest positions (P, 3) of a lab states file's surface points, phantom frame.

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
    return np.nanmedian(points, axis=0)

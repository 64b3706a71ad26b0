"""Evaluation over a lump and away from it: a model right elsewhere and wrong over the lump
should not look fine.

A lump (the twin's ``synth --inclusion``, or one a user names) is a centre on the footprint
(phantom frame, m) and a radius. A test example is *over* it where its press is within the
radius plus :data:`LUMP_REACH_M` of the centre (the tip's (x, y) at the example's first state:
where the press is on the surface), else *away*. Each part gets the model's metrics beside the
no-learning references on the same examples, the gain over the best of them, and the
intervals' coverage where the run keeps intervals (a row's
:class:`~data_schema.metrics_doc.LumpRow`).

The reach is how far from the lump a press still deforms the surface the lump shapes, as L_d
measures it over the whole surface: a press beside the lump sinks a dent that reaches over it.
It is not fit-msm --map's :data:`sim.msm.msm_map_fit.REGION_REACH_M` (5 mm), which says which
presses tell a region's stiffness by how deep their tip sinks there, a nearer question.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from core.errors import BadInput
from data_schema.metrics_doc import LumpPart, LumpRow
from data_schema.truth import read_regions
from train.data import StateTensors

LUMP_REACH_M = 0.010       # m beyond the lump's radius that still counts as over it


@dataclass(frozen=True)
class Lump:
    """A lump's centre on the footprint and its radius, m."""

    x: float
    y: float
    radius: float

    def over(self, xy: np.ndarray) -> np.ndarray:
        """Which presses at (x, y) (E, 2) are over the lump (within radius + reach)."""
        return np.hypot(xy[:, 0] - self.x, xy[:, 1] - self.y) <= self.radius + LUMP_REACH_M

    def row(self, over: LumpPart | None, away: LumpPart | None) -> LumpRow:
        """The lump (mm) with its two parts, as a metrics row keeps them."""
        return LumpRow(centre_mm=[self.x * 1e3, self.y * 1e3], radius_mm=self.radius * 1e3,
                       reach_mm=LUMP_REACH_M * 1e3, over=over, away=away)


def parse_lump(text: str) -> Lump:
    """``X,Y,R`` in mm (the centre on the footprint, the radius > 0), else one line."""
    parts = re.split(r"\s*,\s*", str(text).strip())
    try:
        x, y, r = (float(v) for v in parts)
    except ValueError:
        raise BadInput("--lump", f"{text!r}: must be X,Y,R in mm (the centre on the "
                                 "footprint, the radius)") from None
    if not all(map(math.isfinite, (x, y, r))) or r <= 0:
        raise BadInput("--lump", f"{text!r}: X, Y must be finite and R > 0 (mm)")
    return Lump(x * 1e-3, y * 1e-3, r * 1e-3)


def lump_from_truth(path: str | Path) -> Lump:
    """The twin's first inclusion (its centre on the footprint, its radius), else one line."""
    regions = read_regions(path)
    if not len(regions["inclusions/radius"]):
        raise BadInput(path, "the twin has no inclusion: nothing to evaluate over (--lump "
                             "names one by hand)")
    x, y = (float(v) for v in regions["inclusions/footprint"][0])
    return Lump(x, y, float(regions["inclusions/radius"][0]))


def press_xy(states: StateTensors, pairs: torch.Tensor) -> np.ndarray:
    """Where each example's press is (E, 2), m: the tip's (x, y) at its first state."""
    return states.tip[pairs[:, 0], :2].cpu().numpy().astype(np.float64)

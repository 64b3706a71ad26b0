"""A states file's presses as the solid model needs them: where, how hard, and where each point
went.

Each sequence with a rest state (step 0) and loaded states is one press: its place is the tip's
rest position; its loads are the measured force magnitudes, along the file's ``force_vector``
where it has one (simulated states). A lab's states have the magnitude alone: the press's
direction is then the load that moves the model's tip along the tip's measured motion from rest
to its last state (the indenter pushes where it goes; :meth:`MeasuredPress.loads`).

The silicone's top is where the tips rest (their median height): the markers' centres lie
above it, by as much as their rest positions say.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from core.errors import BadInput
from data_schema.hdf5 import attr_text
from data_schema.shape import Shape
from data_schema.states import check_flat_rest, footprint, validate_states
from sim.solid.solid_model import Attachments


@dataclass(frozen=True)
class MeasuredPress:
    """One press: its rest and its loaded states (phantom frame, m; NaN where missing)."""

    sequence: int
    location: int                   # the place's id in the file (repeats share it)
    rest: np.ndarray                # (P + 1, 3) the markers, then the tip
    force: np.ndarray               # (T,) N, the force's magnitude
    motion: np.ndarray              # (3,) unit: the tip's motion from rest to its last state
    states: np.ndarray              # (T, P + 1, 3)
    vectors: np.ndarray | None      # (T, 3) N, the force where the file has it

    def loads(self, tip_compliance: np.ndarray) -> np.ndarray:
        """(T, 3) N: the file's force vectors, else each magnitude along the load that moves
        a tip of ``tip_compliance`` (3 loads, 3: its displacement per unit load along x, y,
        z) along the measured motion."""
        if self.vectors is not None:
            return self.vectors
        direction = self.motion @ np.linalg.inv(tip_compliance)
        direction /= np.linalg.norm(direction)
        return self.force[:, None] * direction[None]


@dataclass(frozen=True)
class MeasuredSet:
    """The presses of a states file, the markers' layout and the footprint."""

    presses: list[MeasuredPress]
    markers: np.ndarray              # (P, 3) the markers' median rest positions
    footprint: tuple[float, float]   # (L, W) m
    top_z: float                     # the silicone's top: where the tips rest
    shape: Shape | None = None       # a curved phantom's (its frame is the states')

    def places(self) -> tuple[np.ndarray, np.ndarray]:
        """(L, 3) each location's place (the mean of its presses' tips at rest), and (presses,)
        which place each press is at."""
        ids, which = np.unique([p.location for p in self.presses], return_inverse=True)
        tips = np.array([p.rest[-1] for p in self.presses])
        return np.array([tips[which == k].mean(axis=0) for k in range(len(ids))]), which

    def attachments(self) -> Attachments:
        """The markers riding on the top face at their rest (x, y)."""
        if self.shape is None:
            return Attachments.riding(self.markers, self.top_z)
        return Attachments.riding(self.markers, self.shape.height(self.markers[:, :2]))


def read_presses(path: str | Path, only: np.ndarray | None = None,
                 shape: Shape | None = None) -> MeasuredSet:
    """The presses of ``path`` (``only``: these sequence ids, e.g. a fold's training presses);
    a curved phantom's with its ``shape`` (without one, states resting off z = 0 are
    refused)."""
    validate_states(path)
    with h5py.File(path, "r") as f:
        if attr_text(f.attrs["source"]) == "msm" and "layout" not in f.attrs:
            raise BadInput(path, "an MSM file of every mass has no tip as its last point: fit "
                                 "the solid to lab states (or an MSM simulated with --layout)")
        seq, step = f["states/sequence"][()], f["states/step"][()]
        location = f["states/location"][()]
        points = f["states/points"][()].astype(np.float64)
        force = f["states/force"][()].astype(np.float64)
        vectors = f["states/force_vector"][()].astype(np.float64) \
            if "states/force_vector" in f else None
    size = footprint(path) or (0.1, 0.1)
    ids = np.unique(seq) if only is None else np.intersect1d(np.unique(seq), only)
    presses = []
    for s in ids:
        rows = np.flatnonzero(seq == s)
        rows = rows[np.argsort(step[rows], kind="stable")]
        rest_tip = points[rows[0], -1]
        if step[rows[0]] != 0 or len(rows) < 2 or not np.isfinite(rest_tip).all():
            continue
        presses.append(MeasuredPress(
            int(s), int(location[rows[0]]), points[rows[0]], force[rows[1:]],
            _motion(points[rows, -1]), points[rows[1:]],
            None if vectors is None else vectors[rows[1:]]))
    if not presses:
        raise BadInput(path, "no press with a rest state and a loaded state to fit")
    rests = np.array([p.rest for p in presses])
    if shape is None:
        check_flat_rest(rests[:, :-1], path)
    unseen = np.flatnonzero(~np.isfinite(rests[:, :-1]).all(axis=2).any(axis=0))
    if unseen.size:
        raise BadInput(path, f"point {int(unseen[0])} is missing from every rest state: no place "
                             "on the surface to attach it to")
    return MeasuredSet(presses, np.nanmedian(rests[:, :-1], axis=0), size,
                       float(np.median(rests[:, -1, 2])), shape)


def _motion(tips: np.ndarray) -> np.ndarray:
    """(3,) unit: the tip's motion from rest to its last finite state (straight down where it
    did not move)."""
    finite = np.flatnonzero(np.isfinite(tips).all(axis=1))
    motion = tips[finite[-1]] - tips[0]
    length = np.linalg.norm(motion)
    return motion / length if length > 1e-6 else np.array([0.0, 0.0, -1.0])

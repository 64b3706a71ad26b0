"""Measured states placed on the MSM grid, ready to compare with the model (``fit-msm``).

A ``phantom.states`` file is in the phantom frame, which is the MSM grid's frame (footprint
``[0, L] x [0, W]``, rest surface at z = 0, +z out of the surface), so measured points are
placed on the grid where they are, with no frame of their own to guess. The grid is the one an
MSM file was made on, or for lab states one sized to their ``footprint_m`` (the paper's mass
spacing unless told otherwise; the paper's 100 mm square where the file has no footprint):

- each point follows the bilinear blend of the four masses around its rest (x, y)
  (:mod:`sim.msm.msm_sampling`): MSM states (points = the masses) land on their own mass, lab
  markers between masses;
- the tip (the point at the tip's rest position: the lab's 26th point, the MSM's loaded mass)
  is the contact patch: the masses within ``contact_radius`` of it (at least the nearest, the
  paper's n_n = 1) share the load and the tip follows their mean;
- the load of a state is ``force_vector`` where the file has it (MSM), else the measured force
  magnitude along the tip's overall motion in that press (lab: the indenter pushes where it
  goes; never a guessed sign).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path

import h5py
import numpy as np

from core.errors import BadInput
from core.progress import warn
from data_schema.hdf5 import attr_text
from data_schema.states import check_flat_rest, footprint, validate_states
from sim.msm.msm import MSM, MSMError, MSMParams
from sim.msm.msm_grid import grid_params
from sim.msm.msm_layout import check_inside
from sim.msm.msm_sampling import Sampling, contact_masses, sample_at

TIP_MATCH = 1e-6          # m: a rest point this close to the tip's rest is the tip


@dataclass(frozen=True)
class MeasuredSequence:
    """One sequence in the grid (= phantom) frame: rest and loaded states of its points."""

    sequence: int            # its id in the file
    contact_radius: float    # m: the load is shared by the masses this close to the tip
    contact: np.ndarray      # (M,) masses sharing the load
    sampling: Sampling       # where each point sits on the grid
    is_tip: np.ndarray       # (P,) bool: the point that follows the contact patch
    rest: np.ndarray         # (P, 3) measured rest positions (NaN: missing)
    forces: np.ndarray       # (T, 3) load of each loaded state, in order
    points: np.ndarray       # (T, P, 3) measured positions of each loaded state
    location: int | None = None   # its place: the file's location id (data_schema.places)



def read_measured(path: str | Path, params: MSMParams | None = None,
                  max_sequences: int | None = None, seed: int = 0,
                  contact_radius: float | None = None, only: np.ndarray | None = None,
                  spacing: float | None = None
                  ) -> tuple[list[MeasuredSequence], MSMParams]:
    """The sequences of a states file on the MSM grid, and the grid parameters to fit with.

    For an MSM file the grid (n, size, n_y, size_y, ...) and contact radius are the ones it
    was made with; for lab states a grid over their ``footprint_m`` at ``spacing`` (m; default
    the paper's). ``only`` keeps those sequence ids (the training presses of a fold);
    ``max_sequences`` then keeps that many of them, drawn with ``seed``.
    """
    path = Path(path)
    validate_states(path)
    with h5py.File(path, "r") as f:
        source = attr_text(f.attrs["source"])
        file_params = f.attrs.get("msm_params")
        protocol = json.loads(attr_text(f.attrs.get("protocol", "{}")) or "{}")
        seq, step = f["states/sequence"][()], f["states/step"][()]
        force = f["states/force"][()].astype(float)
        fvec = f["states/force_vector"][()].astype(float) if "states/force_vector" in f else None
        tip = f["states/tip"][()].astype(float)
        location = f["states/location"][()]
        ids = _chosen(np.unique(seq), only, max_sequences, seed, path)
        rows = {int(s): np.flatnonzero(seq == s) for s in ids}
        wanted = np.sort(np.concatenate(list(rows.values())))
        points = dict(zip(wanted.tolist(), f["states/points"][wanted].astype(float),
                          strict=True))
    if params is None:
        params = _file_grid(path, source, file_params, spacing)
    if source != "msm":              # a lab's, a solid's or a prior's moulds: flat, or refused
        rests = np.stack([points[int(r[0])][:-1] for r in rows.values()])
        check_flat_rest(rests, path)
        if source == "lab":          # a marker beyond the surface would be fitted at its edge
            check_inside(rests.reshape(-1, 3), params, path)
    if contact_radius is None:
        contact_radius = float(protocol.get("contact_radius", 0.0)) if source == "msm" else 0.0
    model = MSM(params)
    sequences = []
    for s, r in rows.items():
        r = r[np.argsort(step[r], kind="stable")]
        if step[r[0]] != 0:           # extract left its rest out (the tip hidden, say)
            warn(f"{path}: sequence {s} has no rest state (step 0): left out of the fit")
        elif len(r) >= 2:
            loads = fvec[r[1:]] if fvec is not None else _loads_along_tip(force[r[1:]], tip[r])
            sequences.append(replace(_measured(path, model, s, tip[r[0]],
                                               [points[int(i)] for i in r], loads,
                                               contact_radius), location=int(location[r[0]])))
    if not sequences:
        raise BadInput(path, "no sequence with a rest state and a loaded state to fit")
    return sequences, model.params


def _file_grid(path: Path, source: str, file_params: object, spacing: float | None
               ) -> MSMParams:
    """The grid to place a file's states on: an MSM file's own (``spacing`` then refused: the
    file's grid is what made the states), else one sized to the file's footprint."""
    if source == "msm" and file_params is not None:
        if spacing is not None:
            raise BadInput(path, "an MSM states file carries the grid it was made on: leave "
                                 "out --spacing-mm")
        try:
            return MSMParams(**json.loads(attr_text(file_params)))
        except (TypeError, ValueError, MSMError) as e:
            raise BadInput(path, f"unreadable msm_params attribute ({e})") from None
    size = footprint(path)
    if size is None and spacing is None:
        return MSMParams()                       # a 2.0 file: the paper's grid, as always
    return grid_params(size or MSMParams().footprint, spacing)


def _chosen(ids: np.ndarray, only: np.ndarray | None, most: int | None, seed: int,
            path: Path) -> np.ndarray:
    """The sequence ids to fit: those in ``only``, at most ``most`` of them (seeded)."""
    if only is not None:
        missing = np.setdiff1d(only, ids)
        if len(missing):
            raise BadInput(path, f"has no sequence {int(missing[0])} (asked for by the fold)")
        ids = np.intersect1d(ids, only)
    if most is not None and len(ids) > most:
        ids = np.sort(np.random.default_rng(seed).choice(ids, most, replace=False))
    return ids


def _loads_along_tip(force: np.ndarray, tips: np.ndarray) -> np.ndarray:
    """Lab loads (T, 3): each force magnitude along the tip's motion from rest to its last
    state (the indenter pushes where it goes); straight down where the tip did not move."""
    motion = tips[-1] - tips[0]
    length = np.linalg.norm(motion)
    direction = motion / length if length > 1e-6 else np.array([0.0, 0.0, -1.0])
    return force[:, None] * direction


def _measured(path: Path, model: MSM, sequence: int, tip_rest: np.ndarray,
              states: list[np.ndarray], loads: np.ndarray, contact_radius: float
              ) -> MeasuredSequence:
    """One sequence placed on the grid."""
    rest = states[0]
    if not (np.isfinite(tip_rest).all() and np.isfinite(loads).all()):
        raise BadInput(path, f"sequence {sequence}: the tip at rest or a load is not finite")
    is_tip = np.linalg.norm(rest - tip_rest, axis=1) < TIP_MATCH
    return MeasuredSequence(sequence, contact_radius,
                            contact_masses(model, tip_rest[:2], contact_radius),
                            sample_at(model, rest[:, :2]), is_tip, rest, loads,
                            np.stack(states[1:]))

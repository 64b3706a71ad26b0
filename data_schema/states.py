"""``states.h5`` (``phantom.states`` 2.0): static states and the examples built from them.

One layout serves extracted lab states and MSM simulations, so our trainer and anybody else's
read both alike. Everything is in the *phantom frame*: the rest surface at z = 0, +z out of the
phantom, its footprint on [0, L] x [0, W] m (the MSM's grid on [0, 0.1]^2), so a location means
the same place in MSM and lab data.

- ``states/points`` (S, N, 3): the surface points of each static state (lab: the 25 markers in
  session.toml order, then the indenter tip; MSM: the 32 x 32 masses). ``states/valid`` (S, N)
  is False where a lab marker was missing at that instant (its row of ``points`` is NaN).
- ``states/step`` is the level index t: the state's force level is ``t * step_n`` (root
  attribute, N); ``states/force`` is the force magnitude measured (lab) or applied (MSM).
- ``states/sequence`` is unique in the file: lab, one press (numbered in time order, so within
  a session the n-th sequence is the synced file's n-th press); MSM, location x direction.
  ``states/location`` is a global place id (two sessions share one only when the user says
  so); ``states/session`` indexes the root attribute ``session_names`` (JSON list).
- MSM only: ``states/mass`` the loaded mass, ``states/force_vector`` the applied force (phantom
  frame). Lab only: ``states/speed`` the surface speed at the state (m/s), and
  ``sessions/transform`` (P, 4, 4), each session's source (lab) frame -> phantom frame.
- Examples are index pairs: ``single/*`` (t, t + 1) and ``multi/*`` (t, t + d, d >= 2), both in
  one sequence. An example's input is ``points[start]``, its target ``points[end]``, its
  condition ``C = [tip[start], tip[end]]``, its change of force ``force[end] - force[start]``.

Version 2.0 added the frame, ``valid``, ``session``, ``mass``, ``speed``, the transforms and a
validator of meaning (:func:`validate_states`). 1.0 files are refused: regenerate them.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from core.errors import BadInput
from data_schema.hdf5 import Dataset, H5Schema, attr_text, read_schema_id, validate_h5

STATES = H5Schema(
    name="phantom.states",
    version="2.0",
    root_attrs=("provenance", "source", "units_length", "units_force", "step_n", "frame",
                "session_names"),
    doc=__doc__ or "",
    datasets=(
        Dataset("states/points", "f4", ("S", "N", 3), "m",
                doc="surface points, phantom frame (lab: 25 markers + tip; NaN where invalid)"),
        Dataset("states/valid", "b1", ("S", "N"), doc="False where a lab marker was missing"),
        Dataset("states/tip", "f4", ("S", 3), "m",
                doc="indenter tip (lab) or loaded mass (MSM), phantom frame"),
        Dataset("states/force", "f4", ("S",), "N", doc="force magnitude at the state"),
        Dataset("states/step", "i4", ("S",), doc="level index t: force level t * step_n"),
        Dataset("states/sequence", "i4", ("S",), doc="press (lab) or location x direction (MSM)"),
        Dataset("states/location", "i4", ("S",), doc="global location id"),
        Dataset("states/session", "i4", ("S",), doc="index into the session_names attribute"),
        Dataset("states/mass", "i4", ("S",), required=False, doc="MSM: the loaded mass"),
        Dataset("states/force_vector", "f4", ("S", 3), "N", required=False,
                doc="MSM: applied force, phantom frame"),
        Dataset("states/speed", "f4", ("S",), "m/s", required=False,
                doc="lab: mean surface-marker speed at the state"),
        Dataset("sessions/transform", "f8", ("P", 4, 4), "m", required=False,
                doc="lab: each session's source frame -> phantom frame"),
        Dataset("single/start", "i4", ("E1",), doc="single-step examples: state at t"),
        Dataset("single/end", "i4", ("E1",), doc="single-step examples: state at t + 1"),
        Dataset("multi/start", "i4", ("E2",), doc="multi-step examples: state at t"),
        Dataset("multi/end", "i4", ("E2",), doc="multi-step examples: state at least 2 on"),
    ),
)

PLAUSIBLE_M = 5.0          # no phantom point or tip lies this far from the frame's origin
PLAUSIBLE_N = 1000.0       # no phantom press reaches this force (the Nano17 reads up to ~70 N)
REGENERATE = ("regenerate it with this version's `pipeline simulate` (MSM) or "
              "`pipeline extract` (lab)")


def validate_states(path: str | Path) -> None:
    """Check a states file's layout and meaning; raise :class:`BadInput` naming the first fault.

    Meaning: example indices in range, start and end in one sequence, end after start,
    single-step pairs exactly one level apart, multi-step at least two; every valid point
    finite; coordinates and forces of plausible size for metres and newtons (millimetres or
    millinewtons written as metres or newtons are refused, not learned); one session name per
    session id.
    """
    sid = read_schema_id(path)
    if sid is not None and sid[0] == STATES.name and sid[1].split(".")[0] == "1":
        raise BadInput(path, f"a phantom.states {sid[1]} file (no phantom frame, validity "
                             f"mask or session ids): {REGENERATE}")
    validate_h5(path, STATES)
    with h5py.File(path, "r") as f:
        names = json.loads(attr_text(f.attrs["session_names"]))
        session = f["states/session"][()]
        if session.size and (session.min() < 0 or session.max() >= len(names)):
            raise BadInput(path, "states/session indexes beyond the session_names attribute")
        points, valid = f["states/points"][()], f["states/valid"][()]
        if not np.isfinite(points[valid]).all():
            raise BadInput(path, "a point marked valid is not finite")
        _check_units(path, points[valid], f["states/tip"][()], f["states/force"][()])
        seq, step = f["states/sequence"][()], f["states/step"][()]
        for name, gap in (("single", 1), ("multi", 2)):
            _check_pairs(path, name, f[f"{name}/start"][()], f[f"{name}/end"][()], seq, step, gap)


def _check_units(path: str | Path, points: np.ndarray, tip: np.ndarray, force: np.ndarray
                 ) -> None:
    """Metres and newtons, not millimetres and millinewtons."""
    for what, xyz in (("a surface point", points), ("a tip position", tip)):
        far = float(np.abs(xyz).max()) if xyz.size else 0.0
        if far > PLAUSIBLE_M:
            raise BadInput(path, f"{what} lies {far:.4g} m from the phantom frame's origin "
                                 f"(more than {PLAUSIBLE_M:g} m): are these millimetres? "
                                 "States are in metres")
    big = float(np.abs(force).max()) if force.size else 0.0
    if big > PLAUSIBLE_N:
        raise BadInput(path, f"a force of {big:.4g} N (more than {PLAUSIBLE_N:g} N): are these "
                             "millinewtons? States are in newtons")


def _check_pairs(path: str | Path, name: str, start: np.ndarray, end: np.ndarray,
                 seq: np.ndarray, step: np.ndarray, gap: int) -> None:
    """The examples of one set mean what the layout says."""
    n = len(seq)
    for ends in (start, end):
        bad = np.flatnonzero((ends < 0) | (ends >= n))
        if bad.size:
            raise BadInput(path, f"{name} example {bad[0]} points outside the {n} states")
    faults = {
        "joins two sequences": seq[start] != seq[end],
        "does not move forward": step[end] <= step[start],
        (f"is not {gap} level(s) apart" if gap == 1 else "is less than 2 levels apart"):
            (step[end] - step[start] != 1) if gap == 1 else (step[end] - step[start] < 2),
    }
    for what, bad in faults.items():
        hit = np.flatnonzero(bad)
        if hit.size:
            raise BadInput(path, f"{name} example {hit[0]} ({start[hit[0]]} -> "
                                 f"{end[hit[0]]}) {what}")

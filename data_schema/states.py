"""``states.h5`` (``phantom.states`` 2.3): static states and the examples built from them.

One layout serves extracted lab states and MSM simulations, so our trainer and anybody else's
read both alike. Everything is in the *phantom frame*: the rest surface at z = 0, +z out of the
phantom, its footprint on [0, L] x [0, W] m (root attribute ``footprint_m`` = [L, W]; the MSM's
grid covers the footprint it was made for, the paper's [0, 0.1]^2 by default), so a location
means the same place in MSM and lab data.

- ``states/points`` (S, N, 3): the surface points of each static state (lab: the phantom's
  markers in session.toml order, any number, then the indenter tip; MSM: its masses, or the
  lab's markers and the loaded mass with ``--layout``). Root attribute ``point_names`` (JSON
  list, N names, the tip's "tip") names them where they are markers. ``states/valid`` (S, N)
  is False where a lab marker was missing at that instant (its row of ``points`` is NaN).
- ``states/step`` is the level index t: the state's force level is ``t * step_n`` (root
  attribute, N: the spacing the file was made with, 0.5 N by default; a reader computes a
  level from it, never from a constant); ``states/force`` is the force magnitude measured
  (lab) or applied (MSM).
- ``states/sequence`` is unique in the file: lab, one press (numbered in time order, so within
  a session the n-th sequence is the synced file's n-th press); MSM, location x direction.
  ``states/location`` is a global place id (two sessions share one only when the user says
  so); ``states/session`` indexes the root attribute ``session_names`` (JSON list).
- MSM only: ``states/mass`` the loaded mass, ``states/force_vector`` the applied force (phantom
  frame); MSM drawn from a prior only (2.2, ``simulate --prior``): ``states/phantom`` each
  state's block, and per block its drawn phantom ``phantoms/*`` (springs, contact radius,
  footprint, marker count and pitch, scattered or a grid, occluded share, largest force angle);
  the blocks' marker counts differ, so ``points`` holds the largest count then the tip, the
  slots a block lacks ``valid`` False. Lab only: ``states/speed`` the surface speed at the
  state (m/s), and ``sessions/transform`` (P, 4, 4), each session's source (lab) frame ->
  phantom frame.
- Examples are index pairs: ``single/*`` (t, t + 1) and ``multi/*`` (t, t + d, d >= 2), both in
  one sequence. An example's input is ``points[start]``, its target ``points[end]``, its
  condition ``C = [tip[start], tip[end]]``, its change of force ``force[end] - force[start]``.

Version 2.0 added the frame, ``valid``, ``session``, ``mass``, ``speed``, the transforms and a
validator of meaning (:func:`validate_states`); 2.1 the optional root attributes
``point_names`` and ``footprint_m`` (a 2.0 file is the paper's 100 mm square); 2.2 the
optional ``states/phantom`` and ``phantoms/*`` of a prior's MSM; 2.3 the moulds' ``phantoms/*``
(cap, height, thickness, modulus, stiffening, reach, depth: ``simulate --prior --moulds``, the
solid pressed on curved phantoms drawn from a prior). 1.0 files are refused:
regenerate them.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import h5py
import numpy as np

from core.errors import BadInput
from data_schema.hdf5 import (
    Dataset,
    H5Schema,
    attr_text,
    h5_reading,
    read_schema_id,
    validate_h5,
)

PLAUSIBLE_M = 5.0          # no phantom point or tip lies this far from the frame's origin
PLAUSIBLE_N = 1000.0       # no phantom press reaches this force (the Nano17 reads up to ~70 N)
PLAUSIBLE_M_S = 1.0        # no hand-pressed surface moves this fast at a static state
PLAUSIBLE_LAB_M = 50.0     # no lab frame's origin lies this far from the phantom

STATES = H5Schema(
    name="phantom.states",
    version="2.3",
    root_attrs=("provenance", "source", "units_length", "units_force", "step_n", "frame",
                "session_names"),
    doc=__doc__ or "",
    fixed_attrs={"units_length": "m", "units_force": "N", "frame": "phantom"},
    datasets=(
        Dataset("states/points", "f4", ("S", "N", 3), "m", finite="states/valid",
                limit=PLAUSIBLE_M,
                doc="surface points, phantom frame (lab: the markers + tip; NaN where invalid)"),
        Dataset("states/valid", "b1", ("S", "N"), doc="False where a lab marker was missing"),
        Dataset("states/tip", "f4", ("S", 3), "m", finite=True, limit=PLAUSIBLE_M,
                doc="indenter tip (lab) or loaded mass (MSM), phantom frame"),
        Dataset("states/force", "f4", ("S",), "N", finite=True, limit=PLAUSIBLE_N,
                doc="force magnitude at the state"),
        Dataset("states/step", "i4", ("S",), doc="level index t: force level t * step_n"),
        Dataset("states/sequence", "i4", ("S",), doc="press (lab) or location x direction (MSM)"),
        Dataset("states/location", "i4", ("S",), doc="global location id"),
        Dataset("states/session", "i4", ("S",), doc="index into the session_names attribute"),
        Dataset("states/mass", "i4", ("S",), required=False, doc="MSM: the loaded mass"),
        Dataset("states/force_vector", "f4", ("S", 3), "N", required=False, finite=True,
                limit=PLAUSIBLE_N, doc="MSM: applied force, phantom frame"),
        Dataset("states/phantom", "i4", ("S",), required=False,
                doc="MSM drawn from a prior: each state's block (row of phantoms/*)"),
        Dataset("phantoms/k_between", "f8", ("B",), "N/m", required=False, finite=True),
        Dataset("phantoms/k_fixed", "f8", ("B",), "N/m", required=False, finite=True),
        Dataset("phantoms/contact_radius", "f8", ("B",), "m", required=False, finite=True),
        Dataset("phantoms/footprint", "f8", ("B", 2), "m", required=False, finite=True,
                limit=PLAUSIBLE_M),
        Dataset("phantoms/markers", "i4", ("B",), required=False),
        Dataset("phantoms/pitch", "f8", ("B",), "m", required=False, finite=True),
        Dataset("phantoms/scattered", "b1", ("B",), required=False),
        Dataset("phantoms/missing", "f8", ("B",), required=False, finite=True),
        Dataset("phantoms/max_angle_deg", "f8", ("B",), "deg", required=False, finite=True),
        Dataset("phantoms/cap", "i4", ("B",), required=False,
                doc="moulds: 0 a dome, 1 a ridge along x, 2 along y (mould_prior.Cap)"),
        Dataset("phantoms/height", "f8", ("B",), "m", required=False, finite=True,
                doc="moulds: the cap's height above the rim"),
        Dataset("phantoms/thickness", "f8", ("B",), "m", required=False, finite=True,
                doc="moulds: the block under the rim"),
        Dataset("phantoms/modulus", "f8", ("B",), "Pa", required=False, finite=True),
        Dataset("phantoms/stiffening", "f8", ("B",), "1/m^2", required=False, finite=True),
        Dataset("phantoms/reach", "f8", ("B",), "m", required=False, finite=True),
        Dataset("phantoms/depth", "f8", ("B",), "m", required=False, finite=True,
                doc="moulds: how deep the centre press at 7.5 N goes"),
        Dataset("states/speed", "f4", ("S",), "m/s", required=False, limit=PLAUSIBLE_M_S,
                doc="lab: mean surface-marker speed at the state (NaN: no marker seen)"),
        Dataset("sessions/transform", "f8", ("P", 4, 4), "m", required=False, finite=True,
                limit=PLAUSIBLE_LAB_M, doc="lab: each session's source frame -> phantom frame"),
        Dataset("single/start", "i4", ("E1",), doc="single-step examples: state at t"),
        Dataset("single/end", "i4", ("E1",), doc="single-step examples: state at t + 1"),
        Dataset("multi/start", "i4", ("E2",), doc="multi-step examples: state at t"),
        Dataset("multi/end", "i4", ("E2",), doc="multi-step examples: state at least 2 on"),
    ),
)

REGENERATE = ("regenerate it with this version's `pipeline simulate` (MSM) or "
              "`pipeline extract` (lab)")


def validate_states(path: str | Path) -> None:
    """Check a states file's layout and meaning; raise :class:`BadInput` naming the first fault.

    Layout and values (:data:`STATES`): every valid point, tip and force finite; coordinates
    and forces of plausible size for metres and newtons (millimetres or millinewtons written as
    metres or newtons are refused, not learned). Meaning: ``step_n`` a positive number, one
    session name per session id, levels not negative, example indices in range, start and end
    in one sequence, end after start, single-step pairs exactly one level apart, multi-step at
    least two.
    """
    sid = read_schema_id(path)
    if sid is not None and sid[0] == STATES.name and sid[1].split(".")[0] == "1":
        raise BadInput(path, f"a phantom.states {sid[1]} file (no phantom frame, validity "
                             f"mask or session ids): {REGENERATE}")
    validate_h5(path, STATES)
    with h5_reading(path), h5py.File(path, "r") as f:
        _check_attrs(path, f)
        names = _session_names(path, f.attrs["session_names"])
        _check_ids(path, "states/session", f["states/session"][()], len(names),
                   "the session_names attribute")
        _check_ids(path, "states/step", f["states/step"][()], None, "levels")
        seq, step = f["states/sequence"][()], f["states/step"][()]
        for name, gap in (("single", 1), ("multi", 2)):
            _check_pairs(path, name, f[f"{name}/start"][()], f[f"{name}/end"][()], seq, step, gap)


def example_groups(states: str | Path, group_by: str) -> dict[str, np.ndarray]:
    """The group of every single- and multi-step example (that of its start state)."""
    with h5_reading(states), h5py.File(states, "r") as f:
        group = f[f"states/{group_by}"][()]
        return {name: group[f[f"{name}/start"][()]] for name in ("single", "multi")}


def _check_attrs(path: str | Path, f: h5py.File) -> None:
    step_n = f.attrs["step_n"]
    if not (np.ndim(step_n) == 0 and np.issubdtype(np.asarray(step_n).dtype, np.number)
            and np.isfinite(step_n) and step_n > 0):
        raise BadInput(path, f"root attribute step_n is {step_n!r}, expected a positive number "
                             "of newtons")
    if "point_names" in f.attrs:
        names = _json_list(path, f.attrs["point_names"], "point_names")
        points = f["states/points"].shape[1]
        if len(names) != points or not all(isinstance(n, str) and n for n in names):
            raise BadInput(path, f"root attribute point_names has {len(names)} entries for "
                                 f"{points} points (expected one name each)")
    if "footprint_m" in f.attrs:
        size = np.asarray(f.attrs["footprint_m"])
        if not (size.shape == (2,) and np.issubdtype(size.dtype, np.number)
                and np.isfinite(size).all() and (size > 0).all() and (size < PLAUSIBLE_M).all()):
            raise BadInput(path, f"root attribute footprint_m is {size!r}, expected [L, W] in m")


def point_names(path: str | Path) -> list[str] | None:
    """The states file's point names (None: a file that names none)."""
    with h5_reading(path), h5py.File(path, "r") as f:
        v = f.attrs.get("point_names")
        return None if v is None else json.loads(attr_text(v))


FLAT_REST_M = 5e-3    # a flat phantom's markers rest within this of z = 0 in its frame (sync
                      # refuses 1 mm RMS off their plane)


def rest_off_flat(rest: np.ndarray) -> float:
    """How far (m) rest markers lie off z = 0 at most, each marker at its median height over
    the presses' rest states (``rest``: (R, P, 3), or (P, 3) one layout), so that one press's
    mislabelled marker does not make a flat phantom curved: beyond :data:`FLAT_REST_M`, a
    curved phantom's states (its shape's frame)."""
    z = rest[..., 2].reshape(-1, rest.shape[-2])
    if not np.isfinite(z).any():
        return 0.0
    with warnings.catch_warnings():          # a marker never seen at rest: no height
        warnings.simplefilter("ignore", RuntimeWarning)
        return float(np.nanmax(np.abs(np.nanmedian(z, axis=0))))


def states_source(path: str | Path) -> str:
    """Who made a states file: ``lab`` (extract), ``msm``, ``solid`` or ``moulds``
    (simulate: the MSM, a lab's solid, a prior's moulds); empty where it says nothing."""
    with h5_reading(path), h5py.File(path, "r") as f:
        return attr_text(f.attrs.get("source", ""))


def is_curved(path: str | Path) -> bool:
    """Whether a states file holds a curved phantom's states: its rest markers (level 0, the
    tip aside) lie farther than :data:`FLAT_REST_M` off z = 0."""
    with h5_reading(path), h5py.File(path, "r") as f:
        rest = f["states/points"][np.flatnonzero(f["states/step"][()] == 0)]
    return rest_off_flat(rest[:, :-1]) > FLAT_REST_M


def check_flat_rest(rest: np.ndarray, path: str | Path) -> None:
    """Refuse the states of a curved phantom where a flat block is simulated (the MSM, the
    solid model): rest markers ((R, P, 3) or (P, 3), as :func:`rest_off_flat`) lying
    farther than :data:`FLAT_REST_M` off z = 0."""
    off = rest_off_flat(rest)
    if off > FLAT_REST_M:
        raise BadInput(path, f"its markers rest up to {off * 1e3:.1f} mm off z = 0: a curved "
                             "phantom's states (its shape's frame); the MSM and the solid model "
                             "simulate a flat block")


def footprint(path: str | Path) -> tuple[float, float] | None:
    """The footprint [L, W] (m) the file's frame uses (None: a 2.0 file, the paper's square)."""
    with h5_reading(path), h5py.File(path, "r") as f:
        v = f.attrs.get("footprint_m")
        return None if v is None else (float(v[0]), float(v[1]))


def _session_names(path: str | Path, value: object) -> list:
    """The ``session_names`` attribute: a JSON list of names."""
    return _json_list(path, value, "session_names")


def _json_list(path: str | Path, value: object, name: str) -> list:
    """A root attribute that holds a JSON list of names."""
    try:
        names = json.loads(attr_text(value))
    except (TypeError, ValueError):
        names = None
    if not isinstance(names, list):
        raise BadInput(path, f"root attribute {name} is not a JSON list of names")
    return names


def _check_ids(path: str | Path, name: str, ids: np.ndarray, n: int | None, of: str) -> None:
    """Every id in ``[0, n)`` (``n`` None: not negative)."""
    bad = np.flatnonzero((ids < 0) | (ids >= (n if n is not None else np.inf)))
    if bad.size:
        raise BadInput(path, f"{name}[{bad[0]}] = {ids[bad[0]]} is outside {of}"
                             + (f" (0..{n - 1})" if n is not None else ""))


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

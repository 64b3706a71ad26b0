"""``pipeline extract``: synced files -> static states in the phantom frame (``phantom.states``).

Reads each synced file's presses, moves them into the phantom frame (rest plane from sync's
calibration, in-plane axes from the marker grid: :func:`calib.phantom_frame.to_phantom_frame`),
reads the states off each loading phase (:mod:`calib.static_states`), numbers sequences in time
order across the files, builds the single- and multi-step examples and writes the states file.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import h5py
import numpy as np

from calib.phantom_frame import apply_transform, to_phantom_frame
from calib.static_states import ExtractParams, Press, PressStates, example_pairs, press_states
from core.errors import BadInput
from core.progress import progress
from core.provenance import make_provenance
from data_schema.hdf5 import attr_text, h5_reading, read_schema_id, write_h5
from data_schema.states import STATES, validate_states
from data_schema.synced import SYNCED, validate_synced

DEFAULT_SIZE_M = (0.1, 0.1)


@dataclass
class Session:
    """One synced file read for extraction."""

    name: str
    transform: np.ndarray                  # (4, 4) lab -> phantom
    presses: list[Press]
    locations: list[int]                   # per press, the file's own location id
    n_points: int


@dataclass
class Extracted:
    """The arrays of a states file, and what was left out."""

    arrays: dict[str, np.ndarray]
    session_names: list[str]
    excluded: dict[str, int] = field(default_factory=dict)
    # per session, its presses and their states (empty for an excluded press): for the view
    sessions: list[tuple[list[Press], list[PressStates]]] = field(default_factory=list)


def read_synced(path: str | Path, size_m: tuple[float, float]) -> Session:
    """A synced file's presses in the phantom frame."""
    sid = read_schema_id(path)
    if sid is None or sid[0] != SYNCED.name:
        raise BadInput(path, f"not a synced file (schema {sid[0] if sid else 'none'!r})")
    if sid[1].split(".")[0] != SYNCED.version.split(".")[0]:
        raise BadInput(path, f"synced file of schema version {sid[1]}; this extract reads "
                             f"{SYNCED.version}: re-run `pipeline sync`")
    validate_synced(path)
    with h5_reading(path), h5py.File(path, "r") as f:
        cal = f["calibration"]
        keys = sorted(f["presses"].keys())
        raw = [_press(f["presses"][k]) for k in keys]
        locations = [int(f["presses"][k].attrs["location"]) for k in keys]
        rest = _rest_markers(raw)
        transform = to_phantom_frame(rest, cal["surface_point"][()], cal["surface_normal"][()],
                                     size_m)
        name = attr_text(f.attrs.get("name", Path(path).stem))
    for p in raw:
        p.points = apply_transform(transform, p.points)
    return Session(name, transform, raw, locations, raw[0].points.shape[1])


def _press(g: h5py.Group) -> Press:
    return Press(time_s=g["time_ns"][()].astype(np.int64) * 1e-9, points=g["points"][()],
                 force=g["force_magnitude"][()], onset=int(g.attrs["onset_index"]),
                 peak=int(g.attrs["peak_index"]))


def _rest_markers(presses: list[Press]) -> np.ndarray:
    """Each surface marker's rest position: its median over the frames before every onset."""
    before = np.concatenate([p.points[: p.onset, :-1] for p in presses])
    with warnings.catch_warnings():                # a marker never seen at rest: NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmedian(before, axis=0)


def extract(paths: Sequence[str | Path], params: ExtractParams, seed: int = 0,
            size_m: tuple[float, float] = DEFAULT_SIZE_M, shared_locations: bool = False
            ) -> Extracted:
    """States and examples of every press of every synced file, in file then time order.

    Location ids are the files' own, offset per file unless ``shared_locations`` (the user
    says the same id is the same place in every session).
    """
    cols: dict[str, list] = {k: [] for k in ("points", "valid", "force", "step", "speed",
                                            "sequence", "location", "session")}
    names, transforms, excluded = [], [], {"no_loading_phase": 0, "tip_missing": 0,
                                           "too_fast": 0}
    seq = loc_offset = 0
    views = []
    for s_id, path in enumerate(paths):
        session = read_synced(path, size_m)
        names.append(session.name)
        transforms.append(session.transform)
        pairs = list(zip(session.presses, session.locations, strict=True))
        done = []
        with progress(pairs, f"extracting {Path(path).name}") as bar:
            for press, loc in bar:
                if press.peak <= press.onset:
                    excluded["no_loading_phase"] += 1
                    st = press_states(press, params, levels=False)
                else:
                    st = press_states(press, params)
                    for k, v in st.dropped.items():
                        excluded[k] += v
                    _append(cols, st, seq, loc + loc_offset, s_id)
                done.append(st)
                seq += 1
        views.append((session.presses, done))
        if not shared_locations:
            loc_offset += max(session.locations) + 1
    if not cols["points"]:
        raise BadInput(paths[0], "no static state in any press")
    arrays = {f"states/{k}": np.concatenate(v) for k, v in cols.items()}
    arrays["states/tip"] = arrays["states/points"][:, -1]
    arrays["sessions/transform"] = np.stack(transforms)
    single, multi = example_pairs(arrays["states/step"], arrays["states/sequence"],
                                  np.random.default_rng(seed))
    arrays.update({"single/start": single[:, 0], "single/end": single[:, 1],
                   "multi/start": multi[:, 0], "multi/end": multi[:, 1]})
    return Extracted(arrays, names, excluded, views)


def _append(cols: dict[str, list], st: PressStates, seq: int, loc: int, session: int) -> None:
    n = len(st.step)
    for key in ("points", "valid", "force", "step", "speed"):
        cols[key].append(getattr(st, key))
    for key, value in (("sequence", seq), ("location", loc), ("session", session)):
        cols[key].append(np.full(n, value))


def write_states(out: str | Path, ex: Extracted, params: ExtractParams, seed: int,
                 inputs: Sequence[str | Path]) -> None:
    """The states file, validated in layout and meaning before it takes its final name."""
    prov = make_provenance("extract", {**asdict(params), "seed": seed}, inputs,
                           STATES.name, STATES.version)
    attrs = {"provenance": json.dumps(prov), "source": "lab", "units_length": "m",
             "units_force": "N", "step_n": params.step_n, "frame": "phantom",
             "session_names": json.dumps(ex.session_names),
             "excluded": json.dumps(ex.excluded)}
    write_h5(out, STATES, ex.arrays, attrs)
    validate_states(out)

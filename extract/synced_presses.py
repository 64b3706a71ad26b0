"""A synced file's presses, read for extraction and moved into the phantom frame.

The rest plane is sync's (``calibration/surface_point``, ``surface_normal``); the in-plane axis
and the origin come from the phantom's layout, the file's ``phantom`` attribute
(:mod:`extract.phantom_frame`); a 1.2 file, which has no such attribute, has the paper's
100 mm square grid.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import h5py
import numpy as np

from core.errors import BadInput
from data_schema.hdf5 import attr_text, h5_reading, read_schema_id
from data_schema.phantom import PhantomLayout
from data_schema.synced import FORCE_BITS, SYNCED, validate_synced
from extract.phantom_frame import apply_transform, to_phantom_frame
from extract.static_states import PressSeries

UNTRUSTED = FORCE_BITS["saturated"] | FORCE_BITS["over_range"]


@dataclass
class Session:
    """One synced file read for extraction."""

    path: Path
    name: str
    transform: np.ndarray                  # (4, 4) lab -> phantom
    presses: list[PressSeries]
    locations: list[int]                   # per press, the file's own location id
    point_names: list[str]                 # the phantom markers, then "tip"
    layout: PhantomLayout                  # the footprint and what fixed the frame
    noise_n: float = 0.0                   # sd of the force at rest sync measured (N)


def read_synced(path: str | Path, size_m: tuple[float, float] | None = None) -> Session:
    """A synced file's presses in the phantom frame; ``size_m`` overrides the footprint its
    layout states."""
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
        names = [attr_text(v) for v in f["point_names"][()]]
        layout = _layout(f.attrs.get("phantom"), size_m)
        name = attr_text(f.attrs.get("name", Path(path).stem))
        noise = _force_noise(attr_text(f.attrs["calibration"]))
        point, normal = cal["surface_point"][()], cal["surface_normal"][()]
        to_shape = cal["to_shape"][()] if "to_shape" in cal else None
    return session_from_presses(Path(path), name, raw, locations, names, point, normal, layout,
                                noise, to_shape)


def session_from_presses(path: Path, name: str, presses: list[PressSeries], locations: list[int],
                         names: list[str], surface_point: np.ndarray,
                         surface_normal: np.ndarray, layout: PhantomLayout, noise_n: float,
                         to_shape: np.ndarray | None = None) -> Session:
    """A session's presses (lab frame) in its phantom frame: fixed by the surface markers' rest
    before the presses and the rest plane sync fitted (``pipeline live`` hands its presses
    over here too), or a curved phantom's by sync's registration to its shape, ``to_shape``."""
    try:
        transform = to_shape if to_shape is not None else to_phantom_frame(
            _rest_markers(presses), names[:-1], surface_point, surface_normal, layout)
    except BadInput as e:
        raise BadInput(path, e.what) from None
    for p in presses:
        p.points = apply_transform(transform, p.points)
    return Session(path, name, transform, presses, locations, names, layout, noise_n)


def _layout(attr: object, size_m: tuple[float, float] | None) -> PhantomLayout:
    """The file's phantom layout (absent: the paper's square grid), its size overridden by
    ``size_m`` when given."""
    layout = PhantomLayout.from_json(None if attr is None else json.loads(attr_text(attr)))
    return layout if size_m is None else replace(layout, size_m=(size_m[0], size_m[1]))


def _force_noise(calibration: str) -> float:
    """The force noise (N) sync measured at the log's unloaded start; 0 when not recorded."""
    try:
        value = float(json.loads(calibration)["force"]["noise_force_n"])
    except (ValueError, KeyError, TypeError):
        return 0.0
    return value if np.isfinite(value) and value >= 0 else 0.0


def _press(g: h5py.Group) -> PressSeries:
    """One press; its force is untrusted when sync flagged a frame from onset to release as
    saturated or beyond the rated range (bits of every 1.x file; 1.1 never sets saturated)."""
    onset, release = int(g.attrs["onset_index"]), int(g.attrs["release_index"])
    flags = g["force_quality"][onset:release]
    return PressSeries(time_s=g["time_ns"][()].astype(np.int64) * 1e-9, points=g["points"][()],
                 force=g["force_magnitude"][()], onset=onset, peak=int(g.attrs["peak_index"]),
                 untrusted_force=bool((flags & UNTRUSTED).any()))


def _rest_markers(presses: list[PressSeries]) -> np.ndarray:
    """Each surface marker's rest position: its median over the frames before every onset."""
    before = np.concatenate([p.points[: p.onset, :-1] for p in presses])
    with warnings.catch_warnings():                # a marker never seen at rest: NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmedian(before, axis=0)

"""``simulate --merge``: the shard files of one sharded run joined into the file one run writes.

Each shard (``simulate --shard I/N``) is a complete states file of a contiguous block of
locations; joined in shard order, with the example indices shifted by the states before them,
they give the arrays a one-process run writes, byte for byte. Shards of different runs
(another protocol, model or solver), missing or repeated shards are refused. The runner
(:func:`sim.msm.simulate_stage.run_merge`) records the provenance and writes the file.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from core.errors import BadInput
from data_schema.hdf5 import attr_text
from data_schema.states import validate_states
from sim.msm.msm_dataset import RESIDUAL_ATTRS
from sim.msm.msm_protocol import parse_shard

SAME_ATTRS = ("msm_params", "protocol", "solver", "solid", "layout")
SIMULATED = ("msm", "solid")       # the sources a shard may come from (simulate, --solid)


@dataclass
class Merged:
    """The shards of one run joined: what a one-process run writes, but the provenance."""

    arrays: dict[str, np.ndarray]
    attrs: dict               # root attributes but ``provenance`` (to be set last)
    shards: list[Path]        # the shard files, in shard order
    protocol: dict            # the run's protocol, as its shards record it


def merge_shards(paths: Sequence[str | Path]) -> Merged:
    """Join the shard files of one run into the arrays and root attributes of the states file
    a one-process run writes."""
    if not paths:
        raise BadInput(None, "--merge needs the shard files")
    shards: dict[int, Path] = {}
    first: dict | None = None
    count = None
    for path in map(Path, paths):
        validate_states(path)
        with h5py.File(path, "r") as f:
            attrs = {k: attr_text(f.attrs.get(k, "")) for k in (*SAME_ATTRS, "shard", "source")}
        if attrs["source"] not in SIMULATED or not attrs["shard"]:
            raise BadInput(path, "not a simulated shard (no 'shard' attribute from simulate "
                                 "--shard)")
        i, n = parse_shard(attrs["shard"])
        if first is None:
            first, count = attrs, n
        for key in (*SAME_ATTRS, "source"):
            if attrs[key] != first[key]:
                raise BadInput(path, f"shard of a different run: its {key} differs")
        if n != count:
            raise BadInput(path, f"shard {i}/{n} does not belong to a run of {count} shards")
        if i in shards:
            raise BadInput(path, f"shard {i}/{n} given twice (also {shards[i]})")
        shards[i] = path
    if first is None or count is None:   # no shard read: paths is not empty
        raise BadInput(None, "--merge needs the shard files")
    missing = sorted(set(range(count)) - set(shards))
    if missing:
        raise BadInput(None, f"shards {missing} of {count} are missing")
    parts = []
    for i in range(count):
        with h5py.File(shards[i], "r") as f:
            parts.append({name: f[name][()] for name in _dataset_names(f)})
    arrays = {}
    offset = np.cumsum([0] + [len(p["states/step"]) for p in parts[:-1]])
    for name in parts[0]:
        if name.startswith(("single/", "multi/")):        # state indices: shift per shard
            chunks = [p[name] + o for p, o in zip(parts, offset, strict=True)]
        else:
            chunks = [p[name] for p in parts]
        arrays[name] = np.concatenate(chunks).astype(parts[0][name].dtype)
    root = {k: v for k, v in _root_attrs(shards[0]).items()
            if k not in ("shard", "provenance", "schema", "schema_version")}
    for key in RESIDUAL_ATTRS:
        values = [v for i in range(count) if (v := _root_attrs(shards[i]).get(key)) is not None]
        if len(values) == count:
            root[key] = float(max(values))
    return Merged(arrays, root, [shards[i] for i in range(count)], json.loads(first["protocol"]))


def _dataset_names(f: h5py.File) -> list[str]:
    names: list[str] = []
    f.visititems(lambda name, obj: names.append(name) if isinstance(obj, h5py.Dataset) else None)
    return sorted(names)


def _root_attrs(path: Path) -> dict:
    with h5py.File(path, "r") as f:
        return dict(f.attrs.items())

"""The split stage runner: a states file in, its ``phantom.folds`` 2.0 manifest and recording out.

Defaults follow the paper and the data: lab states group by press (``sequence``), 12:3:5;
MSM states by location, 7:2:1; five folds. The folds themselves are :mod:`split.split`'s; the
view is :mod:`split.split_view`.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import h5py
import numpy as np

from core.atomic import atomic_output, atomic_outputs
from core.errors import BadInput
from core.provenance import make_provenance, sha256_file
from data_schema.hdf5 import h5_reading
from data_schema.json_docs import FOLDS, validate_folds
from data_schema.states import example_groups, states_source, validate_states
from split.split import examples_by_role, make_folds
from split.split_params import DEFAULTS, SplitParams, filled_in
from split.split_view import write_split_recording


def run_split(inputs: str | Path, out: str | Path, params: SplitParams | None = None,
              rrd: str | Path | None = None) -> dict:
    """Split the states file ``inputs`` (the data's defaults where ``params.group_by`` or
    ``params.ratio`` is None); write the manifest ``out`` and the recording ``rrd``
    atomically; returns the manifest, whose provenance records the settings with those
    defaults filled in."""
    states, p = inputs, params or SplitParams()
    doc = build_manifest(states, default_plan(states, p.group_by, p.ratio, p.folds, p.seed))
    with atomic_outputs(out, rrd) as (tmp_out, tmp_rrd):
        write_manifest(tmp_out, doc)
        if tmp_rrd is not None:
            write_split_recording(tmp_rrd, states, doc)
    return doc


def default_plan(states: str | Path, group_by: str | None, ratio: tuple[int, int, int] | None,
                 folds: int, seed: int) -> SplitParams:
    """The settings for ``states``: what the user gave, the data's defaults for the rest."""
    d_group, d_ratio = DEFAULTS.get(states_source(states), DEFAULTS["lab"])   # the file is
    #                                                   checked by build_manifest
    return SplitParams(group_by or d_group, ratio or d_ratio, folds, seed)


def build_manifest(states: str | Path, plan: SplitParams) -> dict:
    """The manifest document for ``states`` under ``plan``, the settings with the data's
    defaults filled in (:func:`default_plan`); validated before it is written."""
    validate_states(states)
    group_by, ratio = filled_in(plan)
    eg = example_groups(states, group_by)
    try:
        folds, note = make_folds(np.concatenate(list(eg.values())), plan,
                                 group_places(states, group_by))
    except BadInput as e:                       # a plan that does not fit: name the file
        raise (BadInput(states, e.what) if e.path is None else e) from None
    out = []
    for fold in folds:
        roles = examples_by_role(eg, fold["groups"])
        out.append({"fold": fold["fold"], **roles,
                    "train_subsets": [[int(x) for x in s] for s in fold["train_subsets"]]})
    groups = len(np.unique(np.concatenate(list(eg.values()))))
    return {
        "schema": FOLDS.name, "schema_version": FOLDS.version,
        "data": {"file": Path(states).name, "sha256": sha256_file(states)},
        "group_by": group_by, "ratio": list(ratio), "seed": plan.seed,
        "groups": groups, "note": note, "folds": out,
        "provenance": make_provenance("split", asdict(plan), [states], FOLDS.name,
                                      FOLDS.version),
    }


def group_places(states: str | Path, group_by: str) -> dict[int, int] | None:
    """Each group's place (``states/location``) where groups are presses; None where they are
    places already."""
    if group_by == "location":
        return None
    with h5_reading(states), h5py.File(states, "r") as f:
        group, place = f[f"states/{group_by}"][()], f["states/location"][()]
    return {int(g): int(p) for g, p in zip(group, place, strict=True)}


def write_manifest(out: str | Path, doc: dict) -> None:
    """Write the manifest atomically; it is checked before it takes its final name."""
    with atomic_output(out) as tmp:
        Path(tmp).write_text(json.dumps(doc, indent=1))
        validate_folds(tmp)

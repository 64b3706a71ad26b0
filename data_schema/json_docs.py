"""JSON documents the pipeline writes: their required keys and types, and one validator.

- ``phantom.msm_params`` 1.3: the spring constants ``pipeline fit-msm`` found (one object),
  and in ``msm_params`` the full MSM parameters, the grid they were fitted on included: ``n``
  masses along x over ``size`` m, ``n_y`` along y over ``size_y`` m (1.1; a 1.0 record has
  ``n`` and ``size`` alone: the square); 1.2: ``map``, the stiffness map of ``fit-msm --map``
  (its regions' ``shape``, ``factors`` row by row along y, their ``sd``, the presses each is
  ``informed_by``, the shrinkage ``weight`` and its ``validation`` table, the distances, a
  ``note``) or null, and ``msm_params.stiffness_map`` the same factors (null or absent:
  uniform, as every 1.0 and 1.1 document reads); 1.3: the map's ``stiffest`` region (its
  ``region`` row and column, ``centre_mm``, ``factor``, ``sd``, and ``peak_mm`` among its
  neighbours; null where none was fitted).
- ``phantom.folds`` 2.0: k-fold split manifests (``pipeline split``) that other trainers read
  and users edit: the states file's name and sha256, the grouping (``sequence`` or
  ``location``), ratio and seed, and per fold ``train``/``val``/``test`` each as
  ``{"groups": [...], "single": [example ids], "multi": [example ids]}`` plus
  ``train_subsets`` (nested lists of 1..n training groups, for the data-scarcity study).
- ``phantom.metrics``: the metrics document of ``pipeline eval``, :mod:`data_schema.metrics_doc`
  (its rows as types) and :mod:`data_schema.intervals_doc` (a row's intervals); they share the
  checks here (:func:`typed_keys`, :func:`check_numbers`, :func:`check_shares`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from core.errors import BadInput


@dataclass(frozen=True)
class JsonSchema:
    """Required keys of a JSON object and the Python types their values must have."""

    name: str
    version: str
    keys: dict[str, type | tuple[type, ...]]


MSM_PARAMS = JsonSchema("phantom.msm_params", "1.3", {
    "schema": str, "schema_version": str, "k_between": float, "k_fixed": float,
    "mean_distance_m": float, "msm_params": dict, "provenance": dict,
})
SOLID_PARAMS = JsonSchema("phantom.solid_params", "1.0", {
    "schema": str, "schema_version": str, "material": dict, "sd": dict, "block": dict,
    "mesh": dict, "labels": dict, "distances_mm": dict, "provenance": dict,
})
FOLDS = JsonSchema("phantom.folds", "2.0", {
    "schema": str, "schema_version": str, "data": dict, "group_by": str, "ratio": list,
    "seed": int, "groups": int, "note": str, "folds": list, "provenance": dict,
})
ROLES = ("train", "val", "test")
SETS = ("single", "multi")


def validate_json_doc(path: str | Path, schema: JsonSchema) -> dict[str, Any]:
    """Read ``path`` and check it against ``schema``; return the document."""
    doc = load_json(path)
    if not isinstance(doc, dict) or doc.get("schema") != schema.name:
        raise BadInput(path, f"not a {schema.name} document")
    if str(doc.get("schema_version", "")).split(".")[0] != schema.version.split(".")[0]:
        raise BadInput(path, f"schema version {doc.get('schema_version')} is not compatible "
                             f"with {schema.version}")
    for key, kind in schema.keys.items():
        if not isinstance(doc.get(key), kind):
            raise BadInput(path, f"key {key!r} missing or not of type {kind}")
    return doc


def validate_folds(path: str | Path) -> dict[str, Any]:
    """Read a ``phantom.folds`` 2.0 manifest and check it; return the document.

    Each fold has the three roles, each with lists of group and example ids; no group and no
    example is in two roles of one fold; every training subset is drawn from the fold's
    training groups, and each subset holds the one before it.
    """
    doc = load_json(path)
    if isinstance(doc, list):
        raise BadInput(path, "a phantom.folds 1.0 list of folds: re-run `pipeline split` to "
                             "write a 2.0 manifest (with the data file's sha256)")
    doc = validate_json_doc(path, FOLDS)
    data = doc["data"]
    if not (isinstance(data.get("file"), str) and isinstance(data.get("sha256"), str)
            and len(data["sha256"]) == 64):
        raise BadInput(path, "data must name the states file and its sha256")
    if doc["group_by"] not in ("sequence", "location"):
        raise BadInput(path, f"group_by must be 'sequence' or 'location', got {doc['group_by']!r}")
    if not doc["folds"]:
        raise BadInput(path, "no folds")
    for i, fold in enumerate(doc["folds"]):
        _check_fold(path, fold, f"fold {i}")
    return doc


def training_sequences(splits: str | Path, fold: int, command: str) -> np.ndarray:
    """The sequence ids of a fold's training presses (a manifest grouped by sequence), for
    ``command`` (its name in the refusal) that fits a model on them."""
    doc = validate_folds(splits)
    if doc.get("group_by") != "sequence":
        raise BadInput(splits, f"{command} --splits needs a manifest grouped by sequence "
                               "(press)")
    if not 0 <= fold < len(doc["folds"]):
        raise BadInput(splits, f"--fold {fold}: it has {len(doc['folds'])} folds")
    return np.asarray(doc["folds"][fold]["train"]["groups"], dtype=np.int64)


def _check_fold(path: str | Path, fold: Any, where: str) -> None:
    if not isinstance(fold, dict) or not all(isinstance(fold.get(r), dict) for r in ROLES):
        raise BadInput(path, "a fold needs train, val and test objects", where=where)
    for key in ("groups", *SETS):
        seen: set[int] = set()
        for role in ROLES:
            ids = fold[role].get(key)
            if not int_list(ids):
                raise BadInput(path, f"{role}.{key} must be a list of integers", where=where)
            if seen & set(ids):
                raise BadInput(path, f"{key} id(s) {sorted(seen & set(ids))[:5]} in two roles",
                               where=where)
            seen |= set(ids)
    train = set(fold["train"]["groups"])
    previous: set[int] = set()
    subsets = fold.get("train_subsets", [])
    if not (isinstance(subsets, list) and all(int_list(s) for s in subsets)):
        raise BadInput(path, "train_subsets must be a list of lists of integers", where=where)
    for n, subset in enumerate(subsets, start=1):
        if len(set(subset)) != n or not set(subset) <= train or not previous <= set(subset):
            raise BadInput(path, f"train subset {n} is not {n} training groups holding "
                                 f"subset {n - 1}", where=where)
        previous = set(subset)


# The plausible size of a number by its key's unit suffix: beyond the phantom's size, a press
UNIT_LIMITS = {"_mm": 100.0, "_n": 1000.0, "_n2": 1e6}
_MISSING = object()


def typed_keys(path: str | Path, obj: Any, keys: Mapping[str, Any], where: str,
               optional: Collection[str] = ()) -> None:
    """``obj`` is an object with ``keys`` (those in ``optional`` may be absent), each of its
    type (a boolean is no number); a key added by hand is left alone, as in every document.
    Shared by the documents' checks (:mod:`data_schema.metrics_doc`,
    :mod:`data_schema.intervals_doc`)."""
    if not isinstance(obj, dict):
        raise BadInput(path, f"{where} is not an object")
    for key, kind in keys.items():
        if key in optional and key not in obj:
            continue
        value = obj.get(key, _MISSING)
        kinds = kind if isinstance(kind, tuple) else (kind,)
        if value is _MISSING or not isinstance(value, kind) or (
                isinstance(value, bool) and bool not in kinds):
            raise BadInput(path, f"{where}.{key} missing or not of type {kind}")


def check_numbers(path: str | Path, values: dict, where: str) -> None:
    """Finite, non-negative numbers, each below the limit its unit suffix sets."""
    for key, value in values.items():
        if not isinstance(value, int | float) or isinstance(value, bool) or \
                not math.isfinite(value) or value < 0:
            raise BadInput(path, f"{where}.{key} is {value!r}: not a finite, non-negative "
                                 "number")
        limit = next((v for suffix, v in UNIT_LIMITS.items() if key.endswith(suffix)), None)
        if limit is not None and value > limit:
            raise BadInput(path, f"{where}.{key} is {value:.4g}, more than a plausible "
                                 f"{limit:g}: in another unit?")


def check_shares(path: str | Path, item: dict, keys: Any, where: str) -> None:
    """Each of ``keys`` that ``item`` has (and is not null) is a share in [0, 1]."""
    for key in keys:
        if item.get(key) is not None and not 0 <= item[key] <= 1:
            raise BadInput(path, f"{where}.{key} is {item[key]!r}: not in [0, 1]")


def check_fold_examples(path: str | Path, doc: dict[str, Any],
                        example_group: Mapping[str, np.ndarray]) -> None:
    """Check a validated manifest against its states file: every example id is one of the
    file's (``example_group``: the group of each example, per set) and lies in a group of the
    role that lists it; every group id is one of the file's."""
    known = set(np.unique(np.concatenate([np.ravel(g) for g in example_group.values()])).tolist())
    for i, fold in enumerate(doc["folds"]):
        for role in ROLES:
            part, where = fold[role], f"fold {i}"
            strange = sorted(set(part["groups"]) - known)
            if strange:
                raise BadInput(path, f"{role}.groups: {doc['group_by']} {strange[0]} is not in "
                                     "the states file", where=where)
            for name in SETS:
                _check_example_ids(path, f"{role}.{name}", part[name], example_group[name],
                                   set(part["groups"]), where)


def _check_example_ids(path: str | Path, key: str, ids: list[int], group: np.ndarray,
                       allowed: set[int], where: str) -> None:
    ids_a = np.asarray(ids, dtype=np.int64)
    out = np.flatnonzero((ids_a < 0) | (ids_a >= len(group)))
    if out.size:
        raise BadInput(path, f"{key}: example id {ids_a[out[0]]} is outside the states file's "
                             f"{len(group)} examples", where=where)
    stray = np.flatnonzero(~np.isin(group[ids_a], list(allowed)))
    if stray.size:
        raise BadInput(path, f"{key}: example {ids_a[stray[0]]} is in group "
                             f"{group[ids_a[stray[0]]]}, not one of this role's groups",
                       where=where)


def int_list(value: Any) -> bool:
    """A list of integers (JSON numbers without a fraction; not booleans)."""
    return isinstance(value, list) and all(isinstance(v, int) and not isinstance(v, bool)
                                           for v in value)


def load_json(path: str | Path) -> Any:
    try:
        return json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise BadInput(path, f"not valid JSON ({e})") from None

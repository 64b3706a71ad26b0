"""JSON documents the pipeline writes: their required keys and types, and one validator.

- ``phantom.msm_params`` 1.1: the spring constants ``pipeline fit-msm`` found (one object),
  and in ``msm_params`` the full MSM parameters, the grid they were fitted on included: ``n``
  masses along x over ``size`` m, ``n_y`` along y over ``size_y`` m (1.1; a 1.0 record has
  ``n`` and ``size`` alone: the square).
- ``phantom.folds`` 2.0: k-fold split manifests (``pipeline split``) that other trainers read
  and users edit: the states file's name and sha256, the grouping (``sequence`` or
  ``location``), ratio and seed, and per fold ``train``/``val``/``test`` each as
  ``{"groups": [...], "single": [example ids], "multi": [example ids]}`` plus
  ``train_subsets`` (nested lists of 1..n training groups, for the data-scarcity study).
- metrics (``pipeline eval --out``): ``runs`` (one row per run: run, label, fold, test_set,
  metrics) and ``overall`` (one row per label: label, test_set, folds, metrics,
  fold_ld_mean_sd_mm), optionally ``scarcity`` rows; ``metrics`` maps ``single``, ``multi``
  and ``all`` to the count ``n`` and the Table-2 numbers in mm, N and N^2.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
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


MSM_PARAMS = JsonSchema("phantom.msm_params", "1.1", {
    "schema": str, "schema_version": str, "k_between": float, "k_fixed": float,
    "mean_distance_m": float, "msm_params": dict, "provenance": dict,
})
FOLDS = JsonSchema("phantom.folds", "2.0", {
    "schema": str, "schema_version": str, "data": dict, "group_by": str, "ratio": list,
    "seed": int, "groups": int, "note": str, "folds": list, "provenance": dict,
})
ROLES = ("train", "val", "test")
SETS = ("single", "multi")
JSON_SCHEMAS = {s.name: s for s in (MSM_PARAMS, FOLDS)}


def validate_json_doc(path: str | Path, schema: JsonSchema) -> dict[str, Any]:
    """Read ``path`` and check it against ``schema``; return the document."""
    doc = _load(path)
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
    doc = _load(path)
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


def _check_fold(path: str | Path, fold: Any, where: str) -> None:
    if not isinstance(fold, dict) or not all(isinstance(fold.get(r), dict) for r in ROLES):
        raise BadInput(path, "a fold needs train, val and test objects", where=where)
    for key in ("groups", *SETS):
        seen: set[int] = set()
        for role in ROLES:
            ids = fold[role].get(key)
            if not _int_list(ids):
                raise BadInput(path, f"{role}.{key} must be a list of integers", where=where)
            if seen & set(ids):
                raise BadInput(path, f"{key} id(s) {sorted(seen & set(ids))[:5]} in two roles",
                               where=where)
            seen |= set(ids)
    train = set(fold["train"]["groups"])
    previous: set[int] = set()
    subsets = fold.get("train_subsets", [])
    if not (isinstance(subsets, list) and all(_int_list(s) for s in subsets)):
        raise BadInput(path, "train_subsets must be a list of lists of integers", where=where)
    for n, subset in enumerate(subsets, start=1):
        if len(set(subset)) != n or not set(subset) <= train or not previous <= set(subset):
            raise BadInput(path, f"train subset {n} is not {n} training groups holding "
                                 f"subset {n - 1}", where=where)
        previous = set(subset)


METRIC_ROWS = {
    "runs": {"run": str, "label": str, "variant": dict, "fold": int, "test_set": str,
             "metrics": dict},
    "overall": {"label": str, "variant": dict, "test_set": str, "folds": int, "metrics": dict,
                "fold_ld_mean_sd_mm": (int, float)},
}
METRIC_LIMITS = {"_mm": 100.0, "_n": 1000.0, "_n2": 1e6}   # beyond the phantom's size, a press
METRIC_SETS = ("single", "multi", "all")


def validate_metrics(path: str | Path) -> dict[str, Any]:
    """Read a metrics document of ``pipeline eval`` and check it; return it.

    Every row has its keys with their types; every metric is a finite, non-negative number of
    plausible size for its unit (an error in micrometres written as millimetres is refused);
    each set counts at least one example.
    """
    doc = _load(path)
    if not isinstance(doc, dict) or not all(isinstance(doc.get(k), list) for k in METRIC_ROWS):
        raise BadInput(path, "not a metrics document (needs lists 'runs' and 'overall')")
    for table, keys in METRIC_ROWS.items():
        for i, row in enumerate(doc[table]):
            where = f"{table}[{i}]"
            if not isinstance(row, dict):
                raise BadInput(path, f"{where} is not an object")
            for key, kind in keys.items():
                if not isinstance(row.get(key), kind) or isinstance(row.get(key), bool):
                    raise BadInput(path, f"{where}.{key} missing or not of type {kind}")
            _check_metric_sets(path, row["metrics"], f"{where}.metrics")
    for i, row in enumerate(doc.get("scarcity", [])):
        if not isinstance(row, dict):
            raise BadInput(path, f"scarcity[{i}] is not an object")
        _check_numbers(path, {k: v for k, v in row.items()   # a reference may have no L_d
                              if k not in ("transfer", "predictor") and v is not None},
                       f"scarcity[{i}]")
    return doc


def _check_metric_sets(path: str | Path, metrics: dict, where: str) -> None:
    if "all" not in metrics or set(metrics) - set(METRIC_SETS):
        raise BadInput(path, f"{where} must hold 'all' and only {METRIC_SETS}")
    for name, values in metrics.items():
        if not isinstance(values, dict) or not isinstance(values.get("n"), int) or \
                values["n"] < 1:
            raise BadInput(path, f"{where}.{name}.n must count at least one example")
        _check_numbers(path, values, f"{where}.{name}")


def _check_numbers(path: str | Path, values: dict, where: str) -> None:
    """Finite, non-negative numbers, each below the limit its unit suffix sets."""
    for key, value in values.items():
        if not isinstance(value, int | float) or isinstance(value, bool) or \
                not math.isfinite(value) or value < 0:
            raise BadInput(path, f"{where}.{key} is {value!r}: not a finite, non-negative "
                                 "number")
        limit = next((v for suffix, v in METRIC_LIMITS.items() if key.endswith(suffix)), None)
        if limit is not None and value > limit:
            raise BadInput(path, f"{where}.{key} is {value:.4g}, more than a plausible "
                                 f"{limit:g}: in another unit?")


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


def _int_list(value: Any) -> bool:
    """A list of integers (JSON numbers without a fraction; not booleans)."""
    return isinstance(value, list) and all(isinstance(v, int) and not isinstance(v, bool)
                                           for v in value)


def _load(path: str | Path) -> Any:
    try:
        return json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise BadInput(path, f"not valid JSON ({e})") from None

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
- ``phantom.metrics`` 1.1 (``pipeline eval --out``): ``runs`` (one row per run: run, label,
  variant, fold, test_set, metrics, references, gain) and ``overall`` (one row per label and
  test set: label, variant, test_set, folds, fold_ids, metrics, fold_ld_mean_sd_mm,
  references, gain, folds_not_beating_references; 1.2: ``intervals``, null where the run
  keeps none), optionally ``scarcity`` rows (fold,
  groups, predictor, ld_mean_mm, ld_max_mm, force_abs_n; 1.3: a model's row ``points_90`` and
  ``force_90``, the shares of test points and examples inside its 90 % intervals, null where
  it keeps none), and its ``provenance``;
  ``metrics`` maps ``single``, ``multi`` and ``all`` to the count ``n`` and the Table-2
  numbers in mm, N and N^2; ``references`` maps each no-learning reference to its ``all``
  metrics (L_d null for one that moves no point); ``gain`` names the best reference of L_d
  and of force with its value and the model's relative gain over it; ``variant`` the run's
  model, training data, rotation, aug, the variant it was fine-tuned from (or null) and
  where its network reads the tip's offsets (1.1: ``offsets``, one of :data:`OFFSETS`; a 1.0
  document has none); ``intervals`` (1.2) per reported level the share of test points inside
  their radius and the mean radius (mm), the share of test examples whose change of force lies
  in its interval and the mean half-width (N), the same at 90 % by distance from the tip's
  path, the mean 90 % radius over the mean L_d, and for a run the calibration's presses and
  examples (1.0 and 1.1 documents have none and are read as they are); ``lump`` (1.4, with
  ``eval --lump`` or ``--truth``) the lump's centre and radius (mm) and reach, and ``over``
  and ``away`` (the test examples whose press is within the radius plus the reach, and the
  rest; null where none is): the model's ``all`` metrics, the references' on the same
  examples, the gain and the intervals' coverage. A document from before
  1.0 (no ``schema``) is refused: re-run ``pipeline eval``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
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


METRICS = JsonSchema("phantom.metrics", "1.5", {
    "schema": str, "schema_version": str, "runs": list, "overall": list, "provenance": dict,
})
METRICS_OPTIONAL = {"scarcity": list}
# The predictors that learn nothing (train/evaluation/references.py), by the names a document keys
# them by
NOTHING_MOVES, NEAREST_PRESS, FORCE_LINEAR = "nothing moves", "nearest press", "force, linear"
REFERENCES = (NOTHING_MOVES, NEAREST_PRESS, FORCE_LINEAR)
_NUMBER = (int, float)
_TEXT_OR_NONE = (str, type(None))
_NUMBER_OR_NONE = (int, float, type(None))
METRIC_ROWS = {
    "runs": {"run": str, "label": str, "variant": dict, "fold": int, "test_set": str,
             "metrics": dict, "references": dict, "gain": dict},
    "overall": {"label": str, "variant": dict, "test_set": str, "folds": int, "fold_ids": list,
                "metrics": dict, "fold_ld_mean_sd_mm": _NUMBER, "references": dict,
                "gain": dict, "folds_not_beating_references": list},
}
ROW_OPTIONAL = {"intervals": (dict, type(None)),   # 1.2: null where the run keeps none
                "lump": dict}                      # 1.4: with eval --lump or --truth
# 1.4: a row's lump (train/evaluation/lump.py): where it is, and per part (over it, away from
# it; null where no test press is) the model's "all" metrics, the references' on the same
# examples, the gain and the intervals' coverage (null where the run keeps none)
LUMP = {"centre_mm": list, "radius_mm": _NUMBER, "reach_mm": _NUMBER, "over": (dict, type(None)),
        "away": (dict, type(None))}
LUMP_PART = {"metrics": dict, "references": dict, "gain": dict, "intervals": (dict, type(None))}
# 1.2: a row's intervals (pipeline eval, train/evaluation/coverage.py): per reported level the
# share of test points inside their radius and the mean radius, the same for the force; by
# distance from the tip's path (the surface's points; the tip's own point, where the data have
# one, apart); the mean radius over mean L_d; a run's calibration
INTERVALS = {"levels": list, "by_distance": list, "radius_to_ld": _NUMBER_OR_NONE}
INTERVALS_OPTIONAL = {"calibration": dict, "tip_point": dict}
INTERVAL_LEVEL = {"level": float, "points": int, "coverage": _NUMBER,
                  "mean_radius_mm": _NUMBER_OR_NONE, "examples": int, "force_coverage": _NUMBER,
                  "force_half_width_n": _NUMBER_OR_NONE}
# 1.5: the [low, high] range each share falls in by chance (train/evaluation/coverage_band.py)
LEVEL_BANDS = {"band": list, "force_band": list}
INTERVAL_NEAR = {"from_mm": _NUMBER, "to_mm": _NUMBER_OR_NONE, "points": int,
                 "coverage": _NUMBER, "mean_radius_mm": _NUMBER_OR_NONE}
CALIBRATION = {"presses": int, "examples": int}
VARIANT = {"model": str, "train_data": str, "rotate": bool, "aug": bool,
           "pretrained": (dict, type(None))}
VARIANT_OPTIONAL = {"offsets": str}      # 1.1: where the network reads the tip's offsets
# Where a network reads each point's offsets from the tip: nowhere (the paper's network), in
# its first graph layer (tip offsets: every graph layer then reads the press), in its heads
OFFSETS = ("none", "graph", "heads")
GAIN = {"ld_reference": _TEXT_OR_NONE, "ld_reference_mm": _NUMBER_OR_NONE,
        "ld_gain": _NUMBER_OR_NONE, "force_reference": _TEXT_OR_NONE,
        "force_reference_n": _NUMBER_OR_NONE, "force_gain": _NUMBER_OR_NONE}
SCARCITY_ROW = {"fold": int, "groups": int, "predictor": str, "ld_mean_mm": _NUMBER_OR_NONE,
                "ld_max_mm": _NUMBER_OR_NONE, "force_abs_n": _NUMBER}
# 1.3: a model's row, the shares of test points and examples inside its 90 % intervals; 1.5:
# the range each falls in by chance
SCARCITY_OPTIONAL = {"points_90": _NUMBER_OR_NONE, "force_90": _NUMBER_OR_NONE,
                     "points_90_low": _NUMBER_OR_NONE, "points_90_high": _NUMBER_OR_NONE,
                     "force_90_low": _NUMBER_OR_NONE, "force_90_high": _NUMBER_OR_NONE}
METRIC_KEYS = ("n", "force_mse_n2", "force_abs_n", "force_abs_sd_n", "ld_mean_mm",
               "ld_mean_sd_mm", "ld_max_mm", "ld_max_sd_mm")
LD_KEYS = ("ld_mean_mm", "ld_mean_sd_mm", "ld_max_mm", "ld_max_sd_mm")  # None: moves no point
METRIC_LIMITS = {"_mm": 100.0, "_n": 1000.0, "_n2": 1e6}   # beyond the phantom's size, a press
METRIC_SETS = ("single", "multi", "all")
_MISSING = object()


def validate_metrics(path: str | Path) -> dict[str, Any]:
    """Read a ``phantom.metrics`` document of ``pipeline eval`` and check every field of it;
    return it.

    Every row has its keys with their types; every metric is a finite, non-negative
    number of plausible size for its unit (an error in micrometres written as millimetres is
    refused), and each set counts at least one example; each reference's metrics alike (L_d
    null for a reference that moves no point); each gain names a reference of its row and is
    at most 1 (a model error below zero); a variant is its fields, recursively through the
    run it was fine-tuned from; the fold lists name folds of the row.
    """
    doc = _load(path)
    if isinstance(doc, dict) and "schema" not in doc and set(METRIC_ROWS) <= set(doc):
        raise BadInput(path, "a metrics document from before phantom.metrics 1.0 (no schema): "
                             "re-run `pipeline eval`")
    doc = validate_json_doc(path, METRICS)
    _typed_keys(path, doc, {**METRICS.keys, **METRICS_OPTIONAL}, "the document",
                optional=METRICS_OPTIONAL)
    for table, keys in METRIC_ROWS.items():
        for i, row in enumerate(doc[table]):
            _check_row(path, row, keys, f"{table}[{i}]")
    for i, row in enumerate(doc.get("scarcity", [])):
        where = f"scarcity[{i}]"
        _typed_keys(path, row, {**SCARCITY_ROW, **SCARCITY_OPTIONAL}, where,
                    optional=SCARCITY_OPTIONAL)
        _check_numbers(path, {k: row[k] for k in SCARCITY_ROW    # a reference may have no L_d
                              if k != "predictor" and row[k] is not None}, where)
        _check_shares(path, row, SCARCITY_OPTIONAL, where)
    return doc


def _check_row(path: str | Path, row: Any, keys: dict, where: str) -> None:
    """One row of ``runs`` or ``overall``: its keys, metrics, references, gain, variant and
    (1.2) intervals."""
    _typed_keys(path, row, {**keys, **ROW_OPTIONAL}, where, optional=ROW_OPTIONAL)
    if row.get("intervals") is not None:
        _check_intervals(path, row["intervals"], f"{where}.intervals")
    if "lump" in row:
        _check_lump(path, row["lump"], set(row["references"]), f"{where}.lump")
    _check_metric_sets(path, row["metrics"], f"{where}.metrics")
    if not row["references"]:
        raise BadInput(path, f"{where}.references is empty")
    strange = sorted(set(row["references"]) - set(REFERENCES))
    if strange:
        raise BadInput(path, f"{where}.references names no reference: {strange} (they are "
                             f"{list(REFERENCES)})")
    for name, values in row["references"].items():
        _check_metric_values(path, values, f"{where}.references[{name!r}]", null_ld=True)
    _check_gain(path, row["gain"], set(row["references"]), f"{where}.gain")
    _check_variant(path, row["variant"], f"{where}.variant")
    if "fold_ids" in row:
        _check_folds(path, row, where)


def _check_intervals(path: str | Path, doc: dict, where: str) -> None:
    """A row's intervals: each level in (0, 1) with shares in [0, 1] over at least one point
    and example, widths finite and plausible or null (unbounded); the distance bins alike."""
    _typed_keys(path, doc, {**INTERVALS, **INTERVALS_OPTIONAL}, where,
                optional=INTERVALS_OPTIONAL)
    if "calibration" in doc:
        _typed_keys(path, doc["calibration"], CALIBRATION, f"{where}.calibration")
    items = [("levels", INTERVAL_LEVEL, f"{where}.levels[{i}]", item)
             for i, item in enumerate(doc["levels"])]
    items += [("by_distance", INTERVAL_NEAR, f"{where}.by_distance[{i}]", item)
              for i, item in enumerate(doc["by_distance"])]
    if "tip_point" in doc:
        items.append(("tip_point", INTERVAL_NEAR, f"{where}.tip_point", doc["tip_point"]))
    for kind, keys, here, item in items:
        if kind == "levels":
            _typed_keys(path, item, {**keys, **LEVEL_BANDS}, here, optional=LEVEL_BANDS)
            _check_bands(path, item, here)
        else:
            _typed_keys(path, item, keys, here)
        if kind == "levels" and not 0 < item["level"] < 1:
            raise BadInput(path, f"{here}.level is {item['level']}: not in (0, 1)")
        _check_shares(path, item, ("coverage", "force_coverage"), here)
        _check_numbers(path, {k: v for k, v in item.items()
                              if v is not None and k not in LEVEL_BANDS}, here)
        if item["points"] < 1 or item.get("examples", 1) < 1:
            raise BadInput(path, f"{here} must count at least one point and example")


def _check_bands(path: str | Path, item: dict, where: str) -> None:
    """Each band a level has is a [low, high] pair of shares, low at most high."""
    for key in LEVEL_BANDS:
        pair = item.get(key)
        if pair is None:
            continue
        if not (len(pair) == 2 and all(isinstance(v, _NUMBER) and not isinstance(v, bool)
                                       and 0 <= v <= 1 for v in pair) and pair[0] <= pair[1]):
            raise BadInput(path, f"{where}.{key} is {pair!r}: not a [low, high] pair of "
                                 "shares in [0, 1]")


def _check_shares(path: str | Path, item: dict, keys: Any, where: str) -> None:
    """Each of ``keys`` that ``item`` has (and is not null) is a share in [0, 1]."""
    for key in keys:
        if item.get(key) is not None and not 0 <= item[key] <= 1:
            raise BadInput(path, f"{where}.{key} is {item[key]!r}: not in [0, 1]")


def _check_lump(path: str | Path, lump: dict, references: set[str], where: str) -> None:
    """A row's lump: its place, and each part's metrics, references, gain and intervals."""
    _typed_keys(path, lump, LUMP, where)
    for part in ("over", "away"):
        got, at = lump[part], f"{where}.{part}"
        if got is None:
            continue
        _typed_keys(path, got, LUMP_PART, at)
        _check_metric_values(path, got["metrics"], f"{at}.metrics")
        for name, values in got["references"].items():
            _check_metric_values(path, values, f"{at}.references[{name!r}]", null_ld=True)
        _check_gain(path, got["gain"], references, f"{at}.gain")
        if got["intervals"] is not None:
            _check_intervals(path, got["intervals"], f"{at}.intervals")


def _check_gain(path: str | Path, gain: dict, references: set[str], where: str) -> None:
    """The best reference of L_d and of force (one of the row's, or null) and the gain over
    it: at most 1 (the model's error is not below zero), null where either is missing."""
    _typed_keys(path, gain, GAIN, where)
    for what in ("ld", "force"):
        name = gain[f"{what}_reference"]
        if name is not None and name not in references:
            raise BadInput(path, f"{where}.{what}_reference {name!r} is not one of the row's "
                                 "references")
        value = gain[f"{what}_gain"]
        if value is not None and not (math.isfinite(value) and value <= 1):
            raise BadInput(path, f"{where}.{what}_gain is {value!r}: not a finite number "
                                 "<= 1")
    _check_numbers(path, {k: gain[k] for k in GAIN if k.endswith(("_mm", "_n"))
                          and gain[k] is not None}, where)


def _check_variant(path: str | Path, variant: Any, where: str) -> None:
    """A run's variant: model, training data, rotation, aug, and the variant it was
    fine-tuned from (null, or a variant)."""
    _typed_keys(path, variant, {**VARIANT, **VARIANT_OPTIONAL}, where,
                optional=VARIANT_OPTIONAL)
    if variant.get("offsets", "none") not in OFFSETS:
        raise BadInput(path, f"{where}.offsets is {variant['offsets']!r}, not one of "
                             f"{list(OFFSETS)}")
    if variant["pretrained"] is not None:
        _check_variant(path, variant["pretrained"], f"{where}.pretrained")


def _check_folds(path: str | Path, row: dict, where: str) -> None:
    """``fold_ids``: one per fold pooled; the folds not beating the references among them."""
    ids, worse = row["fold_ids"], row["folds_not_beating_references"]
    if not (_int_list(ids) and _int_list(worse)):
        raise BadInput(path, f"{where}: fold_ids and folds_not_beating_references must be "
                             "lists of integers")
    if len(ids) != row["folds"] or not set(worse) <= set(ids):
        raise BadInput(path, f"{where}: fold_ids must list its {row['folds']} folds, and "
                             "folds_not_beating_references only folds of them")
    _check_numbers(path, {"fold_ld_mean_sd_mm": row["fold_ld_mean_sd_mm"]}, where)


def _typed_keys(path: str | Path, obj: Any, keys: dict, where: str,
                optional: Mapping[str, Any] = MappingProxyType({})) -> None:
    """``obj`` is an object with ``keys`` (those in ``optional`` may be absent), each of its
    type (a boolean is no number); a key added by hand is left alone, as in every document."""
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


def _check_metric_sets(path: str | Path, metrics: dict, where: str) -> None:
    if "all" not in metrics or set(metrics) - set(METRIC_SETS):
        raise BadInput(path, f"{where} must hold 'all' and only {METRIC_SETS}")
    for name, values in metrics.items():
        _check_metric_values(path, values, f"{where}.{name}")


def _check_metric_values(path: str | Path, values: Any, where: str,
                         null_ld: bool = False) -> None:
    """One set's metrics: :data:`METRIC_KEYS`, ``n`` at least 1, the rest finite and
    plausible (with ``null_ld``, the L_d values may be null: a predictor moving no point)."""
    if not isinstance(values, dict) or not isinstance(values.get("n"), int) or \
            isinstance(values["n"], bool) or values["n"] < 1:
        raise BadInput(path, f"{where}.n must count at least one example")
    if not set(METRIC_KEYS) <= set(values):
        raise BadInput(path, f"{where} lacks {sorted(set(METRIC_KEYS) - set(values))}")
    _check_numbers(path, {k: v for k, v in values.items()
                          if not (null_ld and k in LD_KEYS and v is None)}, where)


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

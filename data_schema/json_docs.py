"""JSON documents the pipeline writes: their required keys and types, and one validator.

- ``phantom.msm_params``: the spring constants ``pipeline fit-msm`` found (one object).
- ``phantom.folds``: k-fold split manifests, nnU-Net style, a plain list that other trainers
  read and users edit: ``[{"train": [...], "val": [...], "test": [...]}, ...]`` where each
  entry lists example or location ids; ``test`` is optional.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from core.errors import BadInput


@dataclass(frozen=True)
class JsonSchema:
    """Required keys of a JSON object and the Python types their values must have."""

    name: str
    version: str
    keys: dict[str, type | tuple[type, ...]]


MSM_PARAMS = JsonSchema("phantom.msm_params", "1.0", {
    "schema": str, "schema_version": str, "k_between": float, "k_fixed": float,
    "mean_distance_m": float, "msm_params": dict, "provenance": dict,
})
FOLD_KEYS = {"train": list, "val": list}
JSON_SCHEMAS = {s.name: s for s in (MSM_PARAMS,)}


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


def validate_folds(path: str | Path) -> list[dict[str, list]]:
    """Read a fold manifest and check that each fold has train and val lists that don't meet."""
    doc = _load(path)
    if not isinstance(doc, list) or not doc:
        raise BadInput(path, "a fold manifest is a non-empty JSON list of folds")
    for i, fold in enumerate(doc):
        if not isinstance(fold, dict) or not all(
                isinstance(fold.get(k), t) for k, t in FOLD_KEYS.items()):
            raise BadInput(path, "fold must be an object with 'train' and 'val' lists",
                           where=f"fold {i}")
        parts = [set(map(str, fold[k])) for k in ("train", "val", "test") if k in fold]
        if sum(map(len, parts)) != len(set().union(*parts)):
            raise BadInput(path, "an id appears in more than one part", where=f"fold {i}")
    return doc


def _load(path: str | Path) -> Any:
    try:
        return json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise BadInput(path, f"not valid JSON ({e})") from None

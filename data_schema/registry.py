"""Every schema the pipeline knows, by name, so a file's `schema` attribute (an HDF5 file's) or
key (a JSON document's) finds its check."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from data_schema.hdf5 import H5Schema, validate_h5
from data_schema.json_docs import (
    FOLDS,
    MSM_PARAMS,
    SOLID_PARAMS,
    validate_folds,
    validate_json_doc,
)
from data_schema.metrics_doc import METRICS, ROW_TABLES, validate_metrics
from data_schema.raw_mcap import RAW_MCAP, McapLayout
from data_schema.states import STATES, validate_states
from data_schema.synced import SYNCED, validate_synced
from data_schema.truth import TRUTH

SCHEMAS: dict[str, H5Schema] = {s.name: s for s in (STATES, SYNCED, TRUTH)}
MCAP_SCHEMAS: dict[str, McapLayout] = {RAW_MCAP.name: RAW_MCAP}   # validate: raw_mcap module


def schema_for(name: str) -> H5Schema | None:
    """The layout registered under ``name`` (a file's ``schema`` attribute), if any."""
    return SCHEMAS.get(name)


# The full check (layout and meaning) of each HDF5 schema; the layout alone where none is more.
VALIDATORS: dict[str, Callable[[str | Path], Any]] = {
    STATES.name: validate_states, SYNCED.name: validate_synced,
    TRUTH.name: lambda path: validate_h5(path, TRUTH),
}


def validator_for(name: str) -> Callable[[str | Path], Any] | None:
    """The check of a file whose ``schema`` attribute is ``name``, if the pipeline knows it."""
    return VALIDATORS.get(name)


# The full check of each JSON document the pipeline writes, by its schema name.
JSON_VALIDATORS: dict[str, Callable[[str | Path], Any]] = {
    FOLDS.name: validate_folds, METRICS.name: validate_metrics,
    MSM_PARAMS.name: lambda path: validate_json_doc(path, MSM_PARAMS),
    SOLID_PARAMS.name: lambda path: validate_json_doc(path, SOLID_PARAMS),
}


def json_validator_for(doc: dict[str, Any]) -> Callable[[str | Path], Any] | None:
    """The check of the JSON document ``doc`` by its ``schema`` name, if the pipeline knows
    it. A document without one that holds the metrics tables is a metrics document older than
    ``phantom.metrics`` 1.0: the metrics check, which says to re-run eval."""
    if "schema" in doc:
        name = doc["schema"]
        return JSON_VALIDATORS.get(name) if isinstance(name, str) else None
    return validate_metrics if set(ROW_TABLES) <= set(doc) else None

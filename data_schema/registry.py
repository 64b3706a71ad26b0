"""Every schema the pipeline knows, by name, so a file's `schema` attribute finds its check."""

from __future__ import annotations

from data_schema.hdf5 import H5Schema
from data_schema.raw_mcap import RAW_MCAP, McapLayout
from data_schema.states import STATES
from data_schema.synced import SYNCED
from data_schema.truth import TRUTH

SCHEMAS: dict[str, H5Schema] = {s.name: s for s in (STATES, SYNCED, TRUTH)}
MCAP_SCHEMAS: dict[str, McapLayout] = {RAW_MCAP.name: RAW_MCAP}   # validate: raw_mcap module


def schema_for(name: str) -> H5Schema | None:
    """The layout registered under ``name`` (a file's ``schema`` attribute), if any."""
    return SCHEMAS.get(name)

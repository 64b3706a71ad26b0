"""Versioned, machine-checkable descriptions of every file the pipeline writes, and validators.

Each file kind has one schema module here (``states``, ``synced``, ``truth``, ``raw_mcap``,
``session``, ``json_docs``). Every stage calls :func:`validate_h5` (or the MCAP/JSON
validator) on what it reads and on what it writes, so a file that does not match its contract
never travels further.
"""

from data_schema.hdf5 import Dataset, H5Schema, read_schema_id, validate_h5
from data_schema.registry import SCHEMAS, schema_for

__all__ = ["Dataset", "H5Schema", "SCHEMAS", "read_schema_id", "schema_for", "validate_h5"]

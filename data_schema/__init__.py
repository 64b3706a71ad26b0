"""Versioned, machine-checkable descriptions of every file the pipeline writes, and validators.

Each file kind has one schema module here (``states``, ``synced``, ``truth``, ``raw_mcap``,
``session``, ``json_docs``). HDF5 files are written by :func:`write_h5` and read by
:func:`read_h5`, which take names, dtypes and units from the layout and validate the file;
every stage checks what it reads and writes against its contract (:func:`validate_h5`, or the
MCAP/JSON validator), so a file that does not match never travels further.
"""

from data_schema.hdf5 import Dataset, H5Schema, read_h5, read_schema_id, validate_h5, write_h5
from data_schema.registry import SCHEMAS, schema_for

__all__ = ["Dataset", "H5Schema", "SCHEMAS", "read_h5", "read_schema_id", "schema_for",
           "validate_h5", "write_h5"]

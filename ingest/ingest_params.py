"""Every setting of ``pipeline ingest`` (the MCAP's provenance records them).

The fields' defaults are the command line's: ``pipeline/ingest_cmd.py`` reads them here.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class IngestParams:
    """Every setting of ``pipeline ingest``."""

    compression: str = "none"     # of the MCAP chunks: none (fast) or zstd (about half the size)

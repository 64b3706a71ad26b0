"""Every setting of ``pipeline ingest`` (the MCAP's provenance records them).

The fields' defaults are the command line's: ``pipeline/ingest_cmd.py`` reads them here.
"""

from __future__ import annotations

from dataclasses import dataclass

from core.errors import BadInput

COMPRESSIONS = ("none", "zstd")   # of the MCAP chunks: none (fast), zstd (about half the size)


@dataclass(frozen=True)
class IngestParams:
    """Every setting of ``pipeline ingest``; bad input, in one line, where one has no
    meaning."""

    compression: str = COMPRESSIONS[0]

    def __post_init__(self) -> None:
        if self.compression not in COMPRESSIONS:
            raise BadInput(None, f"compression {self.compression!r}: must be one of "
                                 f"{', '.join(COMPRESSIONS)}")

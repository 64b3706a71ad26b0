"""Every setting of ``pipeline export``."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ExportParams:
    """Export's settings: none yet (the graph is fixed by the checkpoint)."""

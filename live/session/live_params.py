"""Every setting of ``pipeline live``, and their bounds.

The fields' defaults are the command line's, and its option types refuse what
:class:`LiveParams` refuses, with the bounds stated here: ``pipeline/live_cmd.py`` reads both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from core.errors import BadInput
from live.protocol.address import DEFAULT_HOST, MAX_PORT, QTM_PORT

MAX_TIMEOUT_S = 600.0          # --timeout: in (0, this]; QTM answers in well under a second
MAX_RECONNECT_S = 3600.0       # --reconnect: in [0, this]; longer, a new session is due


@dataclass(frozen=True)
class LiveParams:
    """Every setting of a live session (stored in its MCAP's provenance); bad input, in one
    line naming the setting, where one is out of its bounds."""

    host: str = DEFAULT_HOST
    port: int = QTM_PORT
    duration_s: float | None = None      # stop after this long (None: until QTM stops)
    timeout_s: float = 5.0               # no answer or no frame for this long ends it
    calibration: Path | None = None      # a synced file whose tip calibration to use
    model: Path | None = None            # a trained run whose answer to show beside the press
    spawn: bool = False                  # a rerun viewer beside the recording
    serve: bool = False                  # the recording served to a browser
    states: bool = True                  # sync and extract on the MCAP at the end
    recover: bool = False                # finish a killed session's journal, stream nothing
    reconnect_s: float = 0.0             # after a lost connection, try again this long

    def __post_init__(self) -> None:
        if not 0 < self.port <= MAX_PORT:
            raise BadInput(None, f"port {self.port}: must be in [1, {MAX_PORT}]")
        if self.duration_s is not None and not (math.isfinite(self.duration_s)
                                                and self.duration_s > 0):
            raise BadInput(None, f"duration_s {self.duration_s}: must be > 0 s (or None)")
        if not (math.isfinite(self.timeout_s) and 0 < self.timeout_s <= MAX_TIMEOUT_S):
            raise BadInput(None, f"timeout_s {self.timeout_s}: must be in (0, "
                                 f"{MAX_TIMEOUT_S:g}] s")
        if not (math.isfinite(self.reconnect_s) and 0 <= self.reconnect_s <= MAX_RECONNECT_S):
            raise BadInput(None, f"reconnect_s {self.reconnect_s}: must be in [0, "
                                 f"{MAX_RECONNECT_S:g}] s")

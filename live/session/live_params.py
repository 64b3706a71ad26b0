"""Every setting of ``pipeline live``, and their bounds.

The fields' defaults are the command line's, and its option types refuse what
:class:`LiveParams` refuses, with the bounds stated here: ``pipeline/live_cmd.py`` reads both.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import ClassVar

from core.bounds import Bound, check_bounds
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

    BOUNDS: ClassVar[Mapping[str, Bound]] = MappingProxyType({
        "port": Bound(1, MAX_PORT, whole=True),
        "duration_s": Bound(0, min_open=True, unit="s"),
        "timeout_s": Bound(0, MAX_TIMEOUT_S, min_open=True, unit="s"),
        "reconnect_s": Bound(0, MAX_RECONNECT_S, unit="s"),
    })

    def __post_init__(self) -> None:
        check_bounds(self, self.BOUNDS)

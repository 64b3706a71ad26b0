"""Every setting of ``pipeline replay``, and their bounds.

The fields' defaults are the command line's, and its option types refuse what
:class:`ReplayParams` refuses, with the bounds stated here: ``pipeline/replay_cmd.py`` reads
both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from core.errors import BadInput
from live.protocol.address import DEFAULT_HOST, MAX_PORT, QTM_PORT

MAX_SPEED = 1000.0                # beyond this a 500 Hz stream outruns any client


@dataclass(frozen=True)
class ReplayParams:
    """Every setting of ``pipeline replay``; bad input, in one line naming the setting, where
    one is out of its bounds."""

    port: int = QTM_PORT           # 0: any free port
    host: str = DEFAULT_HOST       # the address listened on (0.0.0.0: every interface)
    speed: float = 1.0             # times real time: 0 < speed <= MAX_SPEED
    max_clients: int = 0           # stop once this many clients have come and gone; 0: never

    def __post_init__(self) -> None:
        if not 0 <= self.port <= MAX_PORT:
            raise BadInput(None, f"port {self.port}: must be in [0, {MAX_PORT}]")
        if not (math.isfinite(self.speed) and 0 < self.speed <= MAX_SPEED):
            raise BadInput(None, f"speed {self.speed}: must be in (0, {MAX_SPEED:g}]")
        if self.max_clients < 0:
            raise BadInput(None, f"max_clients {self.max_clients}: must be >= 0")

"""Every setting of ``pipeline replay``, and their bounds.

The fields' defaults are the command line's: ``pipeline/replay_cmd.py`` reads them here, and
its option types refuse what :func:`check_params` refuses, with the same bounds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from core.errors import BadInput

QTM_PORT = 22223                  # QTM's real-time port for little-endian clients
MAX_SPEED = 1000.0                # beyond this a 500 Hz stream outruns any client


@dataclass(frozen=True)
class ReplayParams:
    """Every setting of ``pipeline replay``."""

    port: int = QTM_PORT           # 0: any free port
    host: str = "127.0.0.1"        # the address listened on (0.0.0.0: every interface)
    speed: float = 1.0             # times real time: 0 < speed <= MAX_SPEED
    max_clients: int = 0           # stop once this many clients have come and gone; 0: never


def check_params(p: ReplayParams) -> None:
    """Bad input naming the setting where one is out of its bounds."""
    if not 0 <= p.port <= 65535:
        raise BadInput(None, f"port {p.port}: must be in [0, 65535]")
    if not (math.isfinite(p.speed) and 0 < p.speed <= MAX_SPEED):
        raise BadInput(None, f"speed {p.speed}: must be in (0, {MAX_SPEED:g}]")
    if p.max_clients < 0:
        raise BadInput(None, f"max_clients {p.max_clients}: must be >= 0")

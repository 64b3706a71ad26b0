"""Every setting of ``pipeline replay``, and their bounds.

The fields' defaults are the command line's, and its option types refuse what
:class:`ReplayParams` refuses, with the bounds stated here: ``pipeline/replay_cmd.py`` reads
both.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import ClassVar

from core.bounds import Bound, check_bounds
from live.protocol.address import DEFAULT_HOST, MAX_PORT, QTM_PORT

MAX_SPEED = 1000.0                # beyond this a 500 Hz stream outruns any client


@dataclass(frozen=True)
class ReplayParams:
    """Every setting of ``pipeline replay``; bad input, in one line naming the setting, where
    one is out of its bounds."""

    port: int = QTM_PORT           # 0: any free port
    host: str = DEFAULT_HOST       # the address listened on (0.0.0.0: every interface)
    speed: float = 1.0             # times real time
    max_clients: int = 0           # stop once this many clients have come and gone; 0: never

    BOUNDS: ClassVar[Mapping[str, Bound]] = MappingProxyType({
        "port": Bound(0, MAX_PORT, whole=True),
        "speed": Bound(0, MAX_SPEED, min_open=True),
        "max_clients": Bound(0, whole=True),
    })

    def __post_init__(self) -> None:
        check_bounds(self, self.BOUNDS)

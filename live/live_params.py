"""Every setting of ``pipeline live``.

The fields' defaults are the command line's: ``pipeline/live_cmd.py`` reads them here.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from core.errors import BadInput

QTM_PORT = 22223               # QTM's real-time server, little-endian


@dataclass(frozen=True)
class LiveParams:
    """Every setting of a live session (stored in its MCAP's provenance)."""

    host: str = "127.0.0.1"
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


def parse_address(text: str) -> tuple[str, int]:
    """``HOST[:PORT]`` as (host, port); QTM's port by default. Bad input when the port is no
    port number."""
    host, _, port = text.rpartition(":") if ":" in text else (text, "", "")
    if not port:
        return text, QTM_PORT
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise BadInput(None, f"--qtm {text!r}: {port!r} is not a port number (1 to 65535)")
    return host or "127.0.0.1", int(port)

"""Where a QTM real-time server is: its port for little-endian clients, the host a client asks
and a server listens on by default, and ``HOST[:PORT]`` read from the command line."""

from __future__ import annotations

from core.errors import BadInput

QTM_PORT = 22223                 # QTM's real-time port for little-endian clients
DEFAULT_HOST = "127.0.0.1"       # this machine: QTM beside the client, the replay beside it
MAX_PORT = 65535                 # a TCP port is 1 to this (0 asks a server for any free one)


def source_name(host: str, port: int) -> str:
    """How messages name the server at ``host``:``port``."""
    return f"QTM RT {host}:{port}"


def parse_address(text: str) -> tuple[str, int]:
    """``HOST[:PORT]`` as (host, port): QTM's port where none is given, this machine where the
    host is left out (``:22224``). Bad input when the port is no port number."""
    host, colon, port = text.rpartition(":")
    if not colon:
        return text, QTM_PORT
    if not port.isdigit() or not 0 < int(port) <= MAX_PORT:
        raise BadInput(None, f"--qtm {text!r}: {port!r} is not a port number (1 to {MAX_PORT})")
    return host or DEFAULT_HOST, int(port)

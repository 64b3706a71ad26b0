"""Provenance of every output: schema version, code version, command, parameters, input hashes."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from collections.abc import Iterable, Mapping
from datetime import UTC, datetime
from functools import lru_cache
from pathlib import Path
from typing import Any

from core import __version__
from core.text import to_json


def sha256_file(path: str | Path, block: int = 1 << 20) -> str:
    """Content hash of a file, streamed so large recordings need no memory."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(block):
            h.update(chunk)
    return h.hexdigest()


@lru_cache(maxsize=1)
def code_version() -> str:
    """Package version plus the git commit when run from a checkout (``0.1.0+g1a2b3c4``)."""
    try:
        out = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=Path(__file__).resolve().parent,
            capture_output=True, text=True, timeout=5, check=False,
        )
        if out.returncode == 0 and out.stdout.strip():
            return f"{__version__}+g{out.stdout.strip()}"
    except (OSError, subprocess.SubprocessError):
        pass
    return __version__


def make_provenance(
    stage: str,
    params: Mapping[str, Any],
    inputs: Iterable[str | Path] = (),
    schema: str | None = None,
    schema_version: str | None = None,
) -> dict[str, Any]:
    """The provenance record a stage stores in each output (as JSON text in HDF5/MCAP)."""
    return {
        "schema": schema,
        "schema_version": schema_version,
        "stage": stage,
        "code_version": code_version(),
        "command": " ".join(sys.argv),
        "params": json.loads(to_json(dict(params))),
        "inputs": {str(p): sha256_file(p) for p in inputs},
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
    }


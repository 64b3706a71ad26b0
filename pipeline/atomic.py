"""Write outputs under a temporary name and rename them into place only when complete.

A crash or a bad input never leaves a half-written file under the final name.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path


def _tmp_name(final: Path) -> Path:
    return final.with_name(f".{final.name}.tmp-{os.getpid()}")


@contextlib.contextmanager
def atomic_outputs(*paths: str | Path | None) -> Iterator[list[Path | None]]:
    """Yield temporary paths beside ``paths``; rename them all into place if the block succeeds.

    ``None`` entries stay ``None`` (an optional output that is switched off). On any exception
    every temporary file is removed and no final path is touched.
    """
    finals = [None if p is None else Path(p) for p in paths]
    tmps = [None if f is None else _tmp_name(f) for f in finals]
    for f in finals:
        if f is not None:
            f.parent.mkdir(parents=True, exist_ok=True)
    try:
        yield tmps
        for f, t in zip(finals, tmps, strict=True):
            if f is not None:
                os.replace(t, f)
    finally:
        for t in tmps:
            if t is not None:
                with contextlib.suppress(FileNotFoundError):
                    t.unlink()


@contextlib.contextmanager
def atomic_output(path: str | Path) -> Iterator[Path]:
    """One-file form of :func:`atomic_outputs`."""
    with atomic_outputs(path) as (tmp,):
        yield tmp

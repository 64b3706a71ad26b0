"""Write outputs under a temporary name and rename them into place only when complete.

A crash or a bad input never leaves a half-written file under the final name.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from contextlib import AbstractContextManager
from pathlib import Path
from typing import overload

from core.errors import BadInput


def same_path(a: str | Path, b: str | Path) -> bool:
    """Whether two paths name the same file (after making them absolute, resolving links)."""
    return Path(a).resolve() == Path(b).resolve()


def _tmp_name(final: Path) -> Path:
    return final.with_name(f".{final.name}.tmp-{os.getpid()}")


@overload
def atomic_outputs(out: str | Path, /) -> AbstractContextManager[tuple[Path]]: ...


@overload
def atomic_outputs(out: str | Path, rrd: str | Path | None, /
                   ) -> AbstractContextManager[tuple[Path, Path | None]]: ...


@overload
def atomic_outputs(*paths: str | Path | None) -> AbstractContextManager[tuple[Path | None, ...]]:
    ...


def atomic_outputs(*paths: str | Path | None) -> AbstractContextManager[tuple[Path | None, ...]]:
    """Yield temporary paths beside ``paths``; rename them all into place if the block succeeds.

    ``None`` entries stay ``None`` (an optional output that is switched off). On any exception
    every temporary file is removed and no final path is touched; a :class:`BadInput` about a
    temporary file (an output refused by its own check) names the output the user asked for.
    Naming one path twice is a programming error (ValueError): the second file would silently
    replace the first. A path given yields a temporary path: an output and its optional
    recording, ``(out, rrd)``, yield a path and a path or None.
    """
    return _temporaries(*paths)


@contextlib.contextmanager
def _temporaries(*paths: str | Path | None) -> Iterator[tuple[Path | None, ...]]:
    """:func:`atomic_outputs`' work."""
    finals = [None if p is None else Path(p) for p in paths]
    named = [f for f in finals if f is not None]
    for i, f in enumerate(named):
        if any(same_path(f, g) for g in named[:i]):
            raise ValueError(f"atomic_outputs: {f} is named twice")
    renames = {f: _tmp_name(f) for f in named}          # final -> temporary, in order
    tmps = tuple(None if f is None else renames[f] for f in finals)
    for f in named:
        try:
            f.parent.mkdir(parents=True, exist_ok=True)
        except (FileExistsError, NotADirectoryError):
            raise BadInput(f, "cannot create its folder: a file is in the way") from None
    try:
        yield tmps
        for f, t in renames.items():
            os.replace(t, f)
    except BadInput as e:
        final = {str(t): f for f, t in renames.items()}
        if e.path in final:
            raise BadInput(final[e.path], e.what, e.where) from None
        raise
    finally:
        for t in renames.values():
            with contextlib.suppress(FileNotFoundError):
                t.unlink()


@contextlib.contextmanager
def atomic_output(path: str | Path) -> Iterator[Path]:
    """One-file form of :func:`atomic_outputs`."""
    with atomic_outputs(path) as (tmp,):
        yield tmp

"""Options shared by several commands, so each is spelled and documented once."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from core.atomic import same_path
from core.errors import BadInput
from core.recording import default_rrd_path


def rrd_option(f: Callable[..., Any]) -> Callable[..., Any]:
    """``--rrd PATH`` (default: beside the output) and ``--no-rrd``."""
    f = click.option(
        "--no-rrd", is_flag=True, help="Do not write a rerun recording."
    )(f)
    return click.option(
        "--rrd", type=click.Path(dir_okay=False, path_type=Path), default=None,
        help="Rerun recording to write (default: beside the output, .rrd).",
    )(f)


def resolve_rrd(out: Path, rrd: Path | None, no_rrd: bool,
                folder: bool | None = None) -> Path | None:
    """The recording path a stage writes, or None with ``--no-rrd``.

    The default goes beside ``out`` (:func:`~core.recording.default_rrd_path`), or inside
    it when ``out`` is a folder: ``folder`` says so; None: when one exists there or the running
    command declares ``out`` as one (``click.Path(file_okay=False)``, as synth's OUT_DIR). An
    ``--rrd`` naming the ``--out`` file is bad input.
    """
    if no_rrd:
        return None
    if folder is None:
        folder = out.is_dir() or _declared_folder(out)
    path = rrd if rrd is not None else default_rrd_path(out, folder)
    if same_path(path, out):
        raise BadInput(out, "--rrd and --out name the same file")
    return path


def _declared_folder(out: Path) -> bool:
    """Whether the running click command takes ``out`` through a folder-only path parameter."""
    ctx = click.get_current_context(silent=True)
    if ctx is None:
        return False
    return any(isinstance(p.type, click.Path) and not p.type.file_okay
               and p.name is not None and ctx.params.get(p.name) == out
               for p in ctx.command.params)


def seed_option(f: Callable[..., Any]) -> Callable[..., Any]:
    """``--seed N``: every random choice of the command derives from it."""
    return click.option("--seed", type=int, default=0, show_default=True,
                        help="Random seed; same seed, same bytes of data.")(f)

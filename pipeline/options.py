"""Options shared by several commands, so each is spelled and documented once."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from pipeline.recording import default_rrd_path


def rrd_option(f: Callable[..., Any]) -> Callable[..., Any]:
    """``--rrd PATH`` (default: beside the output) and ``--no-rrd``."""
    f = click.option(
        "--no-rrd", is_flag=True, help="Do not write a rerun recording."
    )(f)
    return click.option(
        "--rrd", type=click.Path(dir_okay=False, path_type=Path), default=None,
        help="Rerun recording to write (default: beside the output, .rrd).",
    )(f)


def resolve_rrd(out: Path, rrd: Path | None, no_rrd: bool) -> Path | None:
    """The recording path a stage writes, or None with ``--no-rrd``."""
    if no_rrd:
        return None
    return rrd if rrd is not None else default_rrd_path(out)


def seed_option(f: Callable[..., Any]) -> Callable[..., Any]:
    """``--seed N``: every random choice of the command derives from it."""
    return click.option("--seed", type=int, default=0, show_default=True,
                        help="Random seed; same seed, same bytes of data.")(f)

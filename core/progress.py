"""Progress bars for long work that stay silent with ``--quiet`` (and when not on a terminal)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterable, Iterator
from typing import TypeVar

import click

T = TypeVar("T")

_QUIET = False


def set_quiet(quiet: bool) -> None:
    """Switch every progress bar of this process off (``--quiet``)."""
    global _QUIET
    _QUIET = quiet


@contextlib.contextmanager
def progress(items: Iterable[T], label: str, length: int | None = None) -> Iterator[Iterable[T]]:
    """A click progress bar (counts, rate, ETA) over ``items``, on stderr, unless quiet."""
    stderr = click.get_text_stream("stderr")
    if _QUIET or not stderr.isatty():
        yield items
        return
    with click.progressbar(
        items, length=length, label=label, file=stderr,
        show_pos=True, show_eta=True,
    ) as bar:
        yield bar


def say(text: str) -> None:
    """One progress line on stderr (an epoch's loss, say), unless quiet."""
    if not _QUIET:
        click.echo(text, err=True)


def warn(text: str) -> None:
    """A warning line on stderr, shown even when quiet: something the user must know."""
    click.echo(f"warning: {text}", err=True)

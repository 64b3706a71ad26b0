"""The one exception for bad input: the CLI prints its line and exits with status 2."""

from __future__ import annotations

import re
from pathlib import Path


class BadInput(Exception):
    """An input file (or parameter) is wrong in a way the user must fix.

    The message names the file and, where it applies, the line or frame, so that the CLI can
    print it as one line: ``path:line 12: what is wrong``. A bad parameter has no path: its
    message names the option instead.
    """

    def __init__(self, path: str | Path | None, what: str, where: str | None = None) -> None:
        self.path = None if path is None else str(path)
        self.what = what
        self.where = where
        super().__init__(self.line())

    def line(self) -> str:
        """The one-line message shown to the user (line breaks in ``what`` become spaces)."""
        head = ":".join(p for p in (self.path, self.where) if p)
        what = re.sub(r"\s*\n\s*", " ", self.what.strip())
        return f"{head}: {what}" if head else what

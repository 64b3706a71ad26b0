"""A session folder spoiled one way, then ingested: the refusal every such test checks."""

from __future__ import annotations

import hashlib
import shutil
from collections.abc import Callable
from pathlib import Path

from click.testing import CliRunner

from pipeline.cli import cli


def replace_text(path: Path, old: str, new: str) -> None:
    """Spoil a text file in place: ``old`` (which must be there) becomes ``new``."""
    text = path.read_text()
    assert old in text, f"{old!r} not in {path}"
    path.write_text(text.replace(old, new))


def folder_hash(folder: Path) -> str:
    """The names and bytes of every file below ``folder``: an input must stay as it was."""
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        h.update(p.name.encode() + (p.read_bytes() if p.is_file() else b""))
    return h.hexdigest()


def ingest_spoiled(session: Path, tmp_path: Path, spoil: Callable[[Path], str]
                   ) -> tuple[str, str, Path]:
    """Copy ``session``, ``spoil`` the copy (it returns what the refusal must name) and
    ingest it: refused with exit 2 and one line, no traceback, nothing written, the copy
    untouched. Returns (that line, what ``spoil`` said, the copy)."""
    folder = tmp_path / "session"
    shutil.copytree(session, folder)
    said = spoil(folder)
    before = folder_hash(folder)
    out = tmp_path / "out" / "raw.mcap"
    res = CliRunner().invoke(cli, ["-q", "ingest", str(folder), "--out", str(out)])
    assert res.exit_code == 2, (res.output, res.stderr, res.exception)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in res.stderr, lines
    assert not out.parent.exists() or not list(out.parent.iterdir())
    assert folder_hash(folder) == before
    return lines[0], said, folder

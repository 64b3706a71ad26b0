"""Skip a stage whose inputs, parameters and code are unchanged (content hashes, as DVC does).

A stage run leaves a stamp, ``<first output>.stamp.json``, holding the sha256 of every input
file, the command line and the hash of the package's source. The stage is up to date when a new
stamp computed the same way equals the stored one and every output still exists with the hash
the stamp recorded; anything else (an edited input, another option, changed code, a deleted or
modified output) runs it again. The demo's other record, its times (``demo_times.json``), is
written the same way (:func:`write_doc`).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from functools import lru_cache
from pathlib import Path

from core.atomic import atomic_output
from core.packages import PACKAGES
from core.provenance import sha256_file


@lru_cache(maxsize=1)
def code_hash() -> str:
    """sha256 over the package's Python sources, so a code change makes every stage stale."""
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for pkg in PACKAGES:
        for path in sorted((root / pkg).rglob("*.py")):
            h.update(str(path.relative_to(root)).encode())
            h.update(path.read_bytes())
    return h.hexdigest()


def _files(paths: Sequence[Path]) -> list[Path]:
    """The files behind ``paths``: a folder stands for every file in it."""
    out: list[Path] = []
    for p in paths:
        out += sorted(q for q in p.rglob("*") if q.is_file()) if p.is_dir() else [p]
    return out


def _hashes(paths: Sequence[Path]) -> dict[str, str]:
    return {str(p): sha256_file(p) for p in _files(paths)}


def stamp_path(outputs: Sequence[Path]) -> Path:
    """Where the stamp of a stage that writes ``outputs`` lives."""
    first = outputs[0]
    return first.with_name(first.name + ".stamp.json")


def _key(args: Sequence[str], inputs: Sequence[Path]) -> dict:
    return {"args": list(args), "code": code_hash(), "inputs": _hashes(inputs)}


def is_fresh(args: Sequence[str], inputs: Sequence[Path], outputs: Sequence[Path]) -> bool:
    """Whether the stage's last run had these inputs, arguments and code, and its outputs stand."""
    stamp = stamp_path(outputs)
    if not stamp.is_file() or not all(p.exists() for p in outputs):
        return False
    try:
        stored = json.loads(stamp.read_text())
    except (OSError, json.JSONDecodeError):
        return False
    return stored.get("key") == _key(args, inputs) and stored.get("outputs") == _hashes(outputs)


def write_stamp(args: Sequence[str], inputs: Sequence[Path], outputs: Sequence[Path]) -> None:
    """Record a completed run of the stage (after its outputs are in place)."""
    write_doc(stamp_path(outputs), {"key": _key(args, inputs), "outputs": _hashes(outputs)})


def write_doc(path: Path, doc: dict) -> None:
    """One of the demo's records as JSON, atomically (a temporary name renamed into place)."""
    with atomic_output(path) as tmp:
        Path(tmp).write_text(json.dumps(doc, indent=1, sort_keys=True))

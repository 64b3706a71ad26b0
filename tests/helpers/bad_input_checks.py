"""Every stage against damaged copies of every file it reads (seeded, fast): the harness of the
bad-input tests (``tests/<package>/test_<stage>_bad_inputs.py``).

For each (stage, file) pair a small valid file is built once
(``tests/helpers/bad_input_fixtures.py``), then damaged one way per case
(``tests/helpers/file_damage.py``), and the stage run on each copy through the CLI. No case may end
in a traceback; a refusal is exit status 2 with exactly one line on stderr naming the file and no
output left. The cases run are counted (``COUNTS``), and the count printed at the end
(``tests/test_bad_inputs.py``).
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from click.testing import CliRunner

from core.errors import BadInput
from core.provenance import sha256_file
from data_schema.hdf5 import H5Schema, read_h5
from helpers.file_damage import REFUSE, SAME, Mutation
from pipeline.cli import cli as pipeline_cli

COUNTS: dict[str, int] = {}              # (stage, file) -> cases run
PAIRS = 11
TINY_RUN = ("--epochs", "1", "--batch", "64", "--no-rrd")   # one optimiser step


@dataclass(frozen=True)
class Outcome:
    """What a user sees of a command: exit status, stderr, and whether a traceback escaped."""

    exit_code: int
    stderr: str
    output: str
    exception: BaseException | None = None


@dataclass(frozen=True)
class Pair:
    """A stage and a file it reads: where a case's copy goes, how the stage runs on it, and what
    of its output must match the clean run's (``same``) or pass a check (``valid``)."""

    name: str
    clean: Path
    place: Callable[[Path], Path]                      # case folder -> path of the copy
    run: Callable[[Path, Path], tuple[Outcome, Path]]  # copy, case folder -> outcome, output
    same: Callable[[Path], Any]
    valid: Callable[[Path], Any]


def cli(*args: object) -> Outcome:
    """Run ``pipeline -q <args>`` in-process; what a user would see of it."""
    res = CliRunner().invoke(pipeline_cli, ["-q", *map(str, args)])
    escaped = None if isinstance(res.exception, SystemExit) else res.exception
    return Outcome(res.exit_code, res.stderr, res.output, escaped)


# --- judging a case -------------------------------------------------------------------------

def _judge(pair: Pair, m: Mutation, copy: Path, res: Outcome, out: Path, ref: Any
           ) -> str | None:
    """Why the case fails, or None."""
    if res.exception is not None:
        return f"traceback: {type(res.exception).__name__}: {res.exception}"
    if res.exit_code == 2:
        lines = res.stderr.strip().splitlines()
        if len(lines) != 1 or str(copy) not in lines[0] or "Traceback" in res.output:
            return f"exit 2 but stderr is not one line naming the file: {res.stderr!r}"
        if out.exists():
            return "refused, but left output behind"
        return None
    if m.expect == REFUSE:
        return f"exit {res.exit_code}, expected exit 2 (stderr {res.stderr[-300:]!r})"
    if res.exit_code != 0:
        return f"exit {res.exit_code}: {res.output[-300:]!r}"
    if m.expect == SAME and not _equal(pair.same(out), ref):
        return "accepted with an output that differs from the clean file's"
    try:
        pair.valid(out)
    except BadInput as e:
        return f"accepted with an output that fails its own check: {e}"
    return None


def _equal(a: Any, b: Any) -> bool:
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_equal(a[k], b[k]) for k in a)
    if isinstance(a, np.ndarray | torch.Tensor):
        a, b = np.asarray(a), np.asarray(b)
        return np.array_equal(a, b, equal_nan=a.dtype.kind == "f")
    return a == b


def fuzz(pair: Pair, mutations: list[Mutation], tmp: Path) -> None:
    """Run every mutation of ``pair``'s file; fail with the list of cases that went wrong."""
    folder, copy = _case(pair, tmp / "clean")
    res, out = pair.run(copy, folder)
    assert res.exit_code == 0, res.output
    ref = pair.same(out)
    failures = []
    for i, m in enumerate(mutations):
        folder, copy = _case(pair, tmp / f"case{i:03d}")
        m.apply(copy)
        res, out = pair.run(copy, folder)
        why = _judge(pair, m, copy, res, out, ref)
        if why:
            failures.append(f"{pair.name}: {m.name}: {why}")
    COUNTS[pair.name] = len(mutations)
    assert not failures, f"{len(failures)} of {len(mutations)} cases failed:\n" + \
        "\n".join(failures)


def _case(pair: Pair, folder: Path) -> tuple[Path, Path]:
    """A fresh case folder holding a copy of the pair's clean file where the stage reads it."""
    folder.mkdir()
    copy = pair.place(folder)
    shutil.copyfile(pair.clean, copy)
    return folder, copy


# --- what of an output is compared, and inputs that point at a case's copy ----------------------

def arrays(path: Path, schema: H5Schema) -> dict:
    """An HDF5 output's datasets and attributes but its provenance ({} when there is none)."""
    if not path.exists():
        return {}
    values, attrs = read_h5(path, schema)
    return {**values, **{k: v for k, v in attrs.items() if "provenance" not in k}}


def restamped(manifest: Path, data: Path, folder: Path) -> Path:
    """A copy of ``manifest`` carrying ``data``'s sha256, so the data's own check is reached."""
    doc = json.loads(manifest.read_text())
    doc["data"]["sha256"] = sha256_file(data)
    out = folder / "splits.json"
    out.write_text(json.dumps(doc))
    return out

"""One refusal per file type, word for word, and the count of the bad-input cases of every
(stage, file) pair, run after them all.

The harness, the damage and the clean inputs: ``tests/helpers/bad_input_checks.py``,
``tests/helpers/file_damage.py``, ``tests/helpers/bad_input_fixtures.py``.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers.bad_input_checks import COUNTS, PAIRS, cli
from helpers.file_damage import (
    PickledCall,
    edit_ckpt,
    edit_ds,
    in_state,
    mcap_mutations,
    set_at,
    with_key,
)

pytest_plugins = ["helpers.bad_input_fixtures"]


def _refusal(folder: Path, clean: Path, mutation: Callable[[Path], None],
             args: Callable[[Path], tuple]) -> str:
    """The one line a stage prints for a damaged copy of ``clean``."""
    folder.mkdir()
    copy = folder / clean.name
    shutil.copyfile(clean, copy)
    mutation(copy)
    res = cli(*args(copy))
    assert res.exit_code == 2 and res.exception is None, res.output
    return res.stderr.strip()


def test_each_message_names_the_dataset_index_or_key(clean_lab, clean_dent, tmp_path) -> None:
    """One refusal per file type, checked word for word where it matters."""
    out = tmp_path / "out"
    cases = [
        (clean_lab / "s.mcap",
         next(m.apply for m in mcap_mutations(0) if m.name.startswith("force x")),
         lambda p: ("sync", p, "--out", out),
         "/force/raw block 3: sample 65: value Fz is 1017, more than a plausible 1000"),
        (clean_lab / "synced.h5", edit_ds("presses/000/depth", lambda a: a * 1000),
         lambda p: ("extract", p, "--out", out), "presses/000/depth at frame 0 is "),
        (clean_dent / "states.h5", edit_ds("states/force", set_at((3,), np.nan)),
         lambda p: ("split", p, "--out", out), "states/force is not finite at index (3,) (nan)"),
        (clean_dent / "splits.json", with_key(("folds", 0, "test", "single"), 10**6, append=True),
         lambda p: ("train", "--data", clean_dent / "states.h5", "--splits", p, "--out", out),
         "fold 0: test.single: example id 1000000 is outside the states file's"),
        (clean_dent / "run" / "best.pt", lambda p: torch.save({"model": PickledCall()}, p),
         lambda p: ("export", p, "--onnx", out),
         "holds pickled code (print) that a safe load (weights_only) refuses"),
        (clean_dent / "run" / "best.pt",
         edit_ckpt(in_state(("norm", "centre"), lambda c: [x * 1000 for x in c])),
         lambda p: ("export", p, "--onnx", out), "checkpoint norm.centre is "),
    ]
    for i, (clean, mutation, args, words) in enumerate(cases):
        line = _refusal(tmp_path / f"m{i}", clean, mutation, args)
        assert line.startswith(f"error: {tmp_path / f'm{i}' / clean.name}") and words in line, \
            line


def test_count_of_cases(request) -> None:
    """Every pair ran: print how many cases over how many pairs."""
    if len(COUNTS) < PAIRS:
        pytest.skip(f"only {len(COUNTS)} of {PAIRS} pairs ran")
    line = f"fuzz: {sum(COUNTS.values())} mutation cases over {len(COUNTS)} (stage, file) pairs"
    plugins = request.config.pluginmanager
    with plugins.get_plugin("capturemanager").global_and_fixture_disabled():
        plugins.get_plugin("terminalreporter").write_line(line)
    assert sum(COUNTS.values()) >= 250

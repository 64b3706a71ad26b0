"""pipeline eval against damaged copies of the checkpoint, the folds and the states file it
reads.

The harness, the damage and the clean inputs: ``tests/helpers/bad_input_checks.py``,
``tests/helpers/file_damage.py``, ``tests/helpers/bad_input_fixtures.py``.
"""

from __future__ import annotations

import json
from pathlib import Path

import torch
from helpers.bad_input_checks import Outcome, Pair, cli, fuzz, restamped
from helpers.file_damage import checkpoint_mutations, folds_mutations, states_mutations

pytest_plugins = ["helpers.bad_input_fixtures"]


def _metrics(path: Path) -> dict:
    doc = json.loads(path.read_text())
    return {"overall": doc["overall"], "runs": [{**r, "run": None} for r in doc["runs"]]}


def _run_pointing(clean: Path, folder: Path, data: Path | None = None,
                  splits: Path | None = None) -> Path:
    """A copy of the run ``clean`` in ``folder`` whose best.pt names other data or manifest
    files (each case of a pair puts its damaged copy there: one run serves them all)."""
    state = torch.load(clean / "best.pt", weights_only=True)
    if splits is not None:
        state["meta"]["splits"] = str(splits)
    if data is not None:
        state["meta"]["data"]["file"] = str(data)
    (folder / "run").mkdir(parents=True)
    torch.save(state, folder / "run" / "best.pt")
    return folder / "run"


def test_eval_reads_checkpoint(clean_dent, tmp_path) -> None:
    pair = Pair("eval <- checkpoint", clean_dent / "run" / "best.pt",
                lambda c: (c / "run").mkdir() or c / "run" / "best.pt",
                lambda p, c: (cli("eval", p.parent, "--out", c / "m.json", "--no-rrd"),
                              c / "m.json"),
                _metrics, _metrics)
    fuzz(pair, checkpoint_mutations(clean_dent / "run" / "best.pt"), tmp_path)


def test_eval_reads_folds(clean_dent, tmp_path) -> None:
    live = tmp_path / "live"
    run = _run_pointing(clean_dent / "run", live, splits=live / "splits.json")
    pair = Pair("eval <- folds", clean_dent / "splits.json", lambda c: live / "splits.json",
                lambda p, c: (cli("eval", run, "--out", c / "m.json", "--no-rrd"),
                              c / "m.json"),
                _metrics, _metrics)
    fuzz(pair, folds_mutations(clean_dent / "splits.json"), tmp_path)


def test_eval_reads_states(clean_dent, tmp_path) -> None:
    live = tmp_path / "live"
    run = _run_pointing(clean_dent / "run", live, live / "states.h5", live / "splits.json")

    def evaluate(p: Path, c: Path) -> tuple[Outcome, Path]:
        restamped(clean_dent / "splits.json", p, live)
        return cli("eval", run, "--out", c / "m.json", "--no-rrd"), c / "m.json"
    pair = Pair("eval <- states", clean_dent / "states.h5", lambda c: live / "states.h5", evaluate,
                _metrics, _metrics)
    fuzz(pair, states_mutations(clean_dent / "states.h5"), tmp_path)

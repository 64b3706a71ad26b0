"""pipeline split against damaged copies of the states file it reads.

The harness, the damage and the clean inputs: ``tests/helpers/bad_input_checks.py``,
``tests/helpers/file_damage.py``, ``tests/helpers/bad_input_fixtures.py``.
"""

from __future__ import annotations

import json
from pathlib import Path

from helpers.bad_input_checks import Pair, cli, fuzz
from helpers.file_damage import states_mutations

from data_schema.json_docs import validate_folds

pytest_plugins = ["helpers.bad_input_fixtures"]


def _manifest(path: Path) -> dict:
    doc = json.loads(path.read_text())
    doc.pop("provenance")
    doc["data"].pop("sha256")
    return doc


def test_split_reads_states(clean_dent, tmp_path) -> None:
    pair = Pair("split <- states", clean_dent / "states.h5", lambda c: c / "states.h5",
                lambda p, c: (cli("split", p, "--out", c / "out.json", "--folds", "2",
                                   "--ratio", "2:1:1", "--no-rrd"), c / "out.json"),
                _manifest, validate_folds)
    fuzz(pair, states_mutations(clean_dent / "states.h5"), tmp_path)

"""The valid inputs of the bad-input tests, built once per session, and the order that lets
``tests/test_bad_inputs.py`` count the cases of every pair.

A pytest plugin: each bad-input test module names it in ``pytest_plugins``, so the fixtures are
shared by all of them (one lab session, one dent run) wherever they sit in tests/.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from helpers.bad_input_checks import TINY_RUN, cli
from helpers.cgnn_data import write_dent_states
from helpers.raw_sessions import analytic_session
from ingest.ingest_params import IngestParams
from ingest.mcap_io import write_raw_mcap


@pytest.fixture(scope="session")
def clean_lab(tmp_path_factory) -> Path:
    """A two-press analytic session: MCAP -> synced file -> states (the lab path)."""
    d = tmp_path_factory.mktemp("lab")
    write_raw_mcap(d / "s.mcap", analytic_session(0, presses=2), {}, IngestParams().compression)
    assert cli("sync", d / "s.mcap", "--out", d / "synced.h5", "--no-rrd").exit_code == 0
    assert cli("extract", d / "synced.h5", "--out", d / "st.h5", "--no-rrd").exit_code == 0
    return d


@pytest.fixture(scope="session")
def clean_dent(tmp_path_factory) -> Path:
    """Dent states (6 presses), their 2-fold manifest, a one-step run, its metrics."""
    d = tmp_path_factory.mktemp("dent")
    write_dent_states(d / "states.h5", places=3, steps=4)
    for args in (("split", d / "states.h5", "--out", d / "splits.json", "--folds", "2",
                  "--ratio", "2:1:1", "--no-rrd"),
                 ("train", "--data", d / "states.h5", "--splits", d / "splits.json", "--out",
                  d / "run", *TINY_RUN),
                 ("eval", d / "run", "--out", d / "metrics.json", "--no-rrd")):
        res = cli(*args)
        assert res.exit_code == 0, res.output
    return d


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Run ``test_count_of_cases`` after every pair, wherever the stage folders sort."""
    items.sort(key=lambda item: item.nodeid.endswith("test_bad_inputs.py::test_count_of_cases"))

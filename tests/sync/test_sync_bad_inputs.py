"""pipeline sync against damaged copies of the raw MCAP it reads.

The harness, the damage and the clean inputs: ``tests/helpers/bad_input_checks.py``,
``tests/helpers/file_damage.py``, ``tests/helpers/bad_input_fixtures.py``.
"""

from __future__ import annotations

from helpers.bad_input_checks import Pair, arrays, cli, fuzz
from helpers.file_damage import mcap_mutations

from data_schema.synced import SYNCED, validate_synced

pytest_plugins = ["helpers.bad_input_fixtures"]


def test_sync_reads_raw_mcap(clean_lab, tmp_path) -> None:
    pair = Pair("sync <- raw MCAP", clean_lab / "s.mcap", lambda c: c / "s.mcap",
                lambda p, c: (cli("sync", p, "--out", c / "out.h5", "--no-rrd"), c / "out.h5"),
                lambda out: arrays(out, SYNCED), validate_synced)
    fuzz(pair, mcap_mutations(0), tmp_path)

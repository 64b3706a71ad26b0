"""docs/ARCHITECTURE.md names each file contract with its schema version: the code's, every
time (a version bumped in the code and not in the map fails here)."""

from __future__ import annotations

import re
from pathlib import Path

from data_schema import session
from data_schema.json_docs import FOLDS, MSM_PARAMS, SOLID_PARAMS
from data_schema.metrics_doc import METRICS
from data_schema.raw_mcap import RAW_MCAP
from data_schema.states import STATES
from data_schema.synced import SYNCED
from data_schema.truth import TRUTH
from train.inference import export_stage
from train.training import checkpoint

MAP = Path(__file__).resolve().parents[2] / "docs" / "ARCHITECTURE.md"
NAMED = re.compile(r"`(phantom\.[a-z_]+)` (\d+\.\d+)")


def code_versions() -> dict[str, str]:
    return {**{s.name: s.version for s in (STATES, SYNCED, TRUTH, FOLDS, METRICS, MSM_PARAMS,
                                           SOLID_PARAMS, RAW_MCAP)},
            session.SCHEMA: session.VERSION, checkpoint.SCHEMA[0]: checkpoint.SCHEMA[1],
            export_stage.SCHEMA[0]: export_stage.SCHEMA[1]}


def test_the_map_names_every_schema_at_the_codes_version() -> None:
    code = code_versions()
    named = NAMED.findall(MAP.read_text())
    wrong = sorted({(n, v, code.get(n)) for n, v in named if code.get(n) != v})
    assert not wrong, f"ARCHITECTURE.md's versions against the code's: {wrong}"
    assert set(code) <= {n for n, _ in named}, "a schema the map does not name"

"""pipeline inspect against damaged copies of a metrics file: its verdict is the check.

The harness, the damage and the clean inputs: ``tests/helpers/bad_input_checks.py``,
``tests/helpers/file_damage.py``, ``tests/helpers/bad_input_fixtures.py``.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

from helpers.bad_input_checks import Outcome, Pair, cli, fuzz
from helpers.file_damage import SAME, Mutation, edit_json, json_cuts, with_key

pytest_plugins = ["helpers.bad_input_fixtures"]


def metrics_mutations(path: Path) -> list[Mutation]:
    """Cut short, tables removed, metrics non-finite, negative, in another unit or uncounted."""
    all0 = ("overall", 0, "metrics", "all")
    return json_cuts() + [
        Mutation("runs removed", with_key(("runs",), None)),
        Mutation("overall not a list", with_key(("overall",), {})),
        Mutation("label a number", with_key(("overall", 0, "label"), 3)),
        Mutation("folds removed", with_key(("overall", 0, "folds"), None)),
        Mutation("metrics.all removed", with_key(all0[:-1] + ("all",), None)),
        Mutation("ld_mean_mm NaN", with_key((*all0, "ld_mean_mm"), float("nan"))),
        Mutation("force_mse_n2 inf", with_key((*all0, "force_mse_n2"), float("inf"))),
        Mutation("force_abs_n negative", with_key((*all0, "force_abs_n"), -0.1)),
        Mutation("n zero", with_key((*all0, "n"), 0)),
        Mutation("ld_mean_mm x1000 (um)", edit_json(lambda d: _scaled(d, all0, "ld_mean_mm"))),
        Mutation("ld_max_mm of run 0 as text", with_key(("runs", 0, "metrics", "all",
                                                      "ld_max_mm"), "0.5")),
        Mutation("a key added", with_key(("comment",), "by hand"), SAME),
    ]


def _scaled(doc: dict, keys: tuple, key: str) -> dict:
    """``doc`` with the metric ``key`` under ``keys`` multiplied by 1000."""
    obj = doc
    for k in keys:
        obj = obj[k]
    obj[key] *= 1000
    return doc


def test_inspect_checks_metrics(clean_dent, tmp_path) -> None:
    """inspect summarises a damaged file rather than refusing it: its verdict is the check."""
    def run(p: Path, c: Path) -> tuple[Outcome, Path]:
        res = cli("inspect", p, "--json")
        verdict = json.loads(res.output)["details"].get("valid") if res.exit_code == 0 else ""
        if verdict != "valid" and res.exit_code == 0:     # reported as invalid: a refusal
            res = replace(res, exit_code=2, stderr=f"error: {p}: {verdict}\n")
        return res, c / "never"
    pair = Pair("inspect <- metrics JSON", clean_dent / "metrics.json",
                lambda c: c / "metrics.json", run, lambda out: None, lambda out: None)
    fuzz(pair, metrics_mutations(clean_dent / "metrics.json"), tmp_path)

"""The eval stage runner: trained runs in; the metrics (JSON and Markdown), the recording and,
when asked, the data-scarcity curve out.

Scores every run on its fold's test examples beside the no-learning references
(:mod:`train.evaluate`), retrains for the scarcity study when asked (:mod:`train.scarcity`),
and writes the metrics document, its Table-2 Markdown and the recording
(:mod:`train.eval_view`) atomically: nothing of them is written unless all succeed.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from core.atomic import atomic_outputs, same_path
from core.errors import BadInput
from train.eval_view import write_eval_recording
from train.evaluate import evaluate_runs, table2, test_errors, write_json
from train.scarcity import plot, scarcity_rows, write_csv


def run_eval(runs: Sequence[Path], out: Path, rrd: Path | None = None, device: str = "cpu",
             scarcity: bool = False, scarcity_epochs: int | None = None,
             scarcity_groups: int | None = None) -> tuple[dict, str]:
    """Evaluate ``runs`` into ``out`` (JSON), ``out`` with .md (the table) and ``rrd`` (the
    first run's test examples); returns the metrics document and the table."""
    table_path = out.with_suffix(".md")
    named = [p for p in (out, table_path, rrd) if p is not None]
    if any(same_path(a, b) for i, a in enumerate(named) for b in named[:i]):
        raise BadInput(out, "--out, its table (.md) and --rrd must be three different files")
    result = evaluate_runs(list(runs), device)
    if scarcity:
        result["scarcity"] = _scarcity(runs, out, scarcity_epochs, scarcity_groups, device)
    table = table2(result)
    with atomic_outputs(out, table_path, rrd) as (tmp_json, tmp_table, tmp_rrd):
        write_json(tmp_json, result)
        tmp_table.write_text(table)
        if tmp_rrd is not None:
            first = result["runs"][0]
            write_eval_recording(tmp_rrd, test_errors(runs[0], device)[2],
                                 f"{first['label']}, fold {first['fold']}", table)
    return result, table


def _scarcity(runs: Sequence[Path], out: Path, epochs: int | None, most: int | None,
              device: str) -> list:
    """Each run's scarcity curve (retrained beside ``out``), written as CSV and PNG."""
    rows = []
    for run in runs:
        rows += scarcity_rows(run, out.parent / f"{out.stem}.scarcity_runs", epochs, device,
                              most)
    write_csv(out.with_suffix(".scarcity.csv"), rows)
    plot(out.with_suffix(".scarcity.png"), rows)
    return rows

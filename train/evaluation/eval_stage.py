"""The eval stage runner: trained runs in; the metrics (JSON and Markdown), the recording and,
when asked, the data-scarcity curve out.

Scores every run on its fold's test examples beside the no-learning references
(:mod:`train.evaluation.scoring`), retrains for the scarcity study when asked
(:mod:`train.evaluation.scarcity`), and writes the metrics document (``phantom.metrics``,
:mod:`data_schema.metrics_doc`, with its provenance: the command, the settings, the sha256 of
every run's best.pt and of the states files and manifests they name), its Table-2 Markdown
(:mod:`train.evaluation.metrics_table`), the recording (:mod:`train.evaluation.eval_view`) and
the scarcity curve (CSV, PNG) atomically: nothing of them is written unless all succeed.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict, replace
from pathlib import Path

from core.atomic import atomic_outputs, same_path
from core.errors import BadInput
from core.provenance import make_provenance
from data_schema.metrics_doc import METRICS, ScarcityRow, Scores, validate_metrics
from train.evaluation.coverage import error_ratios
from train.evaluation.eval_params import EvalParams
from train.evaluation.eval_view import write_eval_recording
from train.evaluation.metrics_table import shown_name, table2
from train.evaluation.run_errors import test_errors
from train.evaluation.scarcity import plot, scarcity_rows, write_csv
from train.evaluation.scoring import evaluate_runs, footprint_errors
from train.training.checkpoint import load_checkpoint


def run_eval(inputs: Sequence[Path], out: Path, params: EvalParams | None = None,
             rrd: Path | None = None) -> tuple[Scores, str]:
    """Evaluate the run folders ``inputs`` into ``out`` (JSON), ``out`` with .md (the table)
    and ``rrd`` (the first run's test examples); returns the scores (the document's tables)
    and the table."""
    runs, params = list(inputs), params or EvalParams()
    table_path = out.with_suffix(".md")
    named = [p for p in (out, table_path, rrd) if p is not None]
    if any(same_path(a, b) for i, a in enumerate(named) for b in named[:i]):
        raise BadInput(out, "--out, its table (.md) and --rrd must be three different files")
    lump = params.the_lump()
    scores = evaluate_runs(runs, params.device, lump)
    curve = (out.with_suffix(".scarcity.csv"), out.with_suffix(".scarcity.png")) \
        if params.scarcity else (None, None)
    if params.scarcity:
        scores = replace(scores, scarcity=_scarcity(runs, out, params))
    table = table2(scores)
    doc = scores.to_doc(make_provenance("eval", asdict(params), _inputs(runs, params.truth),
                                        METRICS.name, METRICS.version))
    with atomic_outputs(out, table_path, rrd, *curve) as (tmp_json, tmp_table, tmp_rrd,
                                                          tmp_csv, tmp_png):
        assert tmp_json is not None and tmp_table is not None     # out and its table: named
        tmp_json.write_text(json.dumps(doc, indent=1, allow_nan=False))
        validate_metrics(tmp_json)
        tmp_table.write_text(table)
        if tmp_csv is not None and tmp_png is not None:            # the curve: both or none
            write_csv(tmp_csv, scores.scarcity or [])
            plot(tmp_png, scores.scarcity or [])
        if tmp_rrd is not None:
            first = scores.runs[0]
            title = f"{shown_name(first, scores.runs)}, fold {first.fold}"
            _, run, shown = test_errors(runs[0], params.device)
            ratios = None if run.intervals is None else \
                [error_ratios(run.intervals, b, p) for b, p in shown]
            write_eval_recording(tmp_rrd, shown, title, table, ratios,
                                 footprint_errors(run, lump))
    return scores, table


def _inputs(runs: Sequence[Path], truth: Path | None = None) -> list[Path]:
    """What an evaluation read: each run's best.pt, and the states file and manifest it
    names (each once), and the twin's truth where it named the lump."""
    files: dict[Path, None] = {} if truth is None else {Path(truth): None}
    for run in runs:
        meta = load_checkpoint(run / "best.pt")["meta"]
        for path in (run / "best.pt", Path(meta["data"]["file"]), Path(meta["splits"])):
            files[path] = None
    return list(files)


def _scarcity(runs: Sequence[Path], out: Path, params: EvalParams) -> list[ScarcityRow]:
    """Each run's scarcity curve (retrained beside ``out``)."""
    rows: list[ScarcityRow] = []
    for run in runs:
        rows += scarcity_rows(run, out.parent / f"{out.stem}.scarcity_runs",
                              params.scarcity_epochs, params.device, params.scarcity_groups)
    return rows

"""Rows of a metrics document (data_schema/metrics_doc.py) for tests: every field a test does
not name filled with a plain value, so a test says only what it is about."""

from __future__ import annotations

from typing import Any

from data_schema.intervals_doc import IntervalLevel
from data_schema.metrics_doc import Gain, Metrics, PooledRow, RunRow, SetMetrics


def variant(train_data: str = "Exp", pretrained: dict | None = None) -> dict[str, Any]:
    """A variant as a checkpoint records it: the cGNN on ``train_data``, fine-tuned from
    ``pretrained`` (a variant) or from scratch."""
    return {"model": "cGNN", "train_data": train_data, "rotate": False, "aug": False,
            "pretrained": pretrained, "offsets": "none"}


def metrics(**fields: Any) -> Metrics:
    """One set's metrics: those of ``fields``, the rest plain."""
    return Metrics(**{"n": 1, "force_mse_n2": 0.01, "force_abs_n": 0.1, "force_abs_sd_n": 0.05,
                      "ld_mean_mm": 0.2, "ld_mean_sd_mm": 0.1, "ld_max_mm": 0.5,
                      "ld_max_sd_mm": 0.2, **fields})


def gain(**fields: Any) -> Gain:
    """A gain: those of ``fields``, the rest None (no reference)."""
    return Gain(**{"ld_reference": None, "ld_reference_mm": None, "ld_gain": None,
                   "force_reference": None, "force_reference_n": None, "force_gain": None,
                   **fields})


def _shared(fields: dict[str, Any]) -> dict[str, Any]:
    """What every row has, those of ``fields`` first."""
    return {"label": "cGNN/Exp", "variant": variant(), "test_set": "Exp",
            "metrics": SetMetrics(all=metrics()), "references": {}, "gain": gain(), **fields}


def run_row(**fields: Any) -> RunRow:
    """A run's row: those of ``fields``, the rest plain (fold 0, no intervals, no lump)."""
    return RunRow(**_shared({"run": "runs/run", "fold": 0, **fields}))


def pooled_row(**fields: Any) -> PooledRow:
    """A variant's pooled row: those of ``fields``, the rest plain (one fold, 0)."""
    return PooledRow(**_shared({"folds": 1, "fold_ids": [0], "fold_ld_mean_sd_mm": 0.0,
                                "folds_not_beating_references": [], **fields}))


def level(**fields: Any) -> IntervalLevel:
    """One reported level's coverage: those of ``fields``, the rest plain (90 %, no band)."""
    return IntervalLevel(**{"level": 0.9, "points": 100, "coverage": 0.9,
                            "mean_radius_mm": 0.3, "examples": 10, "force_coverage": 0.9,
                            "force_half_width_n": 0.1, **fields})

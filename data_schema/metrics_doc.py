"""``phantom.metrics`` 1.6 (``pipeline eval --out``): its rows as types, and one validator.

The document holds ``runs`` (one :class:`RunRow` per run: run, label, variant, fold, test_set,
metrics, references, gain) and ``overall`` (one :class:`PooledRow` per variant and test set:
label, variant, test_set, folds, fold_ids, metrics, fold_ld_mean_sd_mm, references, gain,
folds_not_beating_references; 1.2: ``intervals``, null where the run keeps none), optionally
``scarcity`` rows (:class:`ScarcityRow`: fold, groups, predictor, ld_mean_mm, ld_max_mm,
force_abs_n; 1.3: a model's row :class:`ScarcityShares`, the shares of test points and
examples inside its 90 % intervals, null where it keeps none; 1.5: the range each falls in by
chance), and its ``provenance``. ``metrics`` (:class:`SetMetrics`) maps ``single``, ``multi``
and ``all`` to the count ``n`` and the Table-2 numbers in mm, N and N^2 (:class:`Metrics`);
``references`` maps each no-learning reference to its ``all`` metrics (L_d null for one that
moves no point); ``gain`` (:class:`Gain`) names the best reference of L_d and of force with
its value and the model's relative gain over it; ``variant`` the run's model, training data,
rotation, aug, the variant it was fine-tuned from (or null) and where its network reads the
tip's offsets (1.1: ``offsets``, one of :data:`OFFSETS`; a 1.0 document has none; 1.6:
``rotate_force`` false where the force was learnt from unturned examples only, absent
otherwise; the variant's own type is the trainer's, train/training/variant.py); ``intervals`` (1.2,
:mod:`data_schema.intervals_doc`; 1.0 and 1.1 documents have none and are read as they are);
``lump`` (1.4, :class:`LumpRow`, with ``eval --lump`` or ``--truth``) the lump's centre and
radius (mm) and reach, and ``over`` and ``away`` (:class:`LumpPart`: the test examples whose
press is within the radius plus the reach, and the rest; null where none is): the model's
``all`` metrics, the references' on the same examples, the gain and the intervals' coverage.
A document from before 1.0 (no ``schema``) is refused: re-run ``pipeline eval``.

Every key is spelled here once, as a field of its row (:mod:`data_schema.json_rows`); every
other module reads the rows' attributes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from core.errors import BadInput
from data_schema.intervals_doc import Intervals, check_intervals
from data_schema.json_docs import (
    JsonSchema,
    check_numbers,
    check_shares,
    int_list,
    load_json,
    typed_keys,
    validate_json_doc,
)
from data_schema.json_rows import JsonRow, flattened, since_version, written_if_set

# The predictors that learn nothing (train/evaluation/references.py), by the names a document
# keys them by
NOTHING_MOVES, NEAREST_PRESS, FORCE_LINEAR = "nothing moves", "nearest press", "force, linear"
REFERENCES = (NOTHING_MOVES, NEAREST_PRESS, FORCE_LINEAR)


@dataclass(frozen=True)
class VariantRow(JsonRow):
    """A run's variant as written in ``metrics.json`` and a checkpoint's meta (the trainer's
    :class:`~train.training.variant.Variant` reads and writes it): model, training data,
    rotation, aug, the variant it was fine-tuned from, where its network reads the tip's
    offsets (1.1; one of :data:`OFFSETS`) and, only where the rotation left the force's
    examples unturned, ``rotate_force`` false (1.6)."""

    model: str
    train_data: str
    rotate: bool
    aug: bool
    pretrained: VariantRow | None
    offsets: str | None = since_version()
    rotate_force: bool | None = written_if_set()


@dataclass(frozen=True, kw_only=True)
class Metrics(JsonRow):
    """Table 2's numbers over one set of examples; L_d None for a predictor that moves no
    point (the linear force reference)."""

    n: int                            # examples
    force_mse_n2: float
    force_abs_n: float                # mean |dF error|
    force_abs_sd_n: float
    ld_mean_mm: float | None          # mean over examples of the mean distance over points
    ld_mean_sd_mm: float | None
    ld_max_mm: float | None           # mean over examples of the largest distance
    ld_max_sd_mm: float | None


@dataclass(frozen=True, kw_only=True)
class SetMetrics(JsonRow):
    """A row's metrics per set: single-step and multi-step examples (each where there is
    one) and all of them."""

    single: Metrics | None = written_if_set()
    multi: Metrics | None = written_if_set()
    all: Metrics


@dataclass(frozen=True, kw_only=True)
class Gain(JsonRow):
    """The best reference of mean L_d and of force error (None where none has a value), its
    value, and the model's relative gain over it (positive: the model is better; None where
    either value is missing)."""

    ld_reference: str | None
    ld_reference_mm: float | None
    ld_gain: float | None
    force_reference: str | None
    force_reference_n: float | None
    force_gain: float | None


def beats(gain: float | None) -> bool:
    """Whether a gain over the best reference (a :class:`Gain`'s ``ld_gain`` or
    ``force_gain``) is one (above zero, and there)."""
    return gain is not None and gain > 0


@dataclass(frozen=True, kw_only=True)
class LumpPart(JsonRow):
    """The test examples over a lump, or away from it: the model's metrics, the references'
    on the same examples, the gain, and the intervals' coverage (None where the run keeps
    none)."""

    metrics: Metrics
    references: dict[str, Metrics]
    gain: Gain
    intervals: Intervals | None


LUMP_PARTS = ("over", "away")    # a lump row's parts, as its fields name them


@dataclass(frozen=True, kw_only=True)
class LumpRow(JsonRow):
    """A row's lump (1.4): where it is, and its two parts (None where no test press is)."""

    centre_mm: list[float]
    radius_mm: float
    reach_mm: float                   # beyond the radius, a press still counts as over it
    over: LumpPart | None
    away: LumpPart | None

    def parts(self) -> dict[str, LumpPart | None]:
        """Each part by its name in the document (:data:`LUMP_PARTS`): over the lump, then
        away from it."""
        return dict(zip(LUMP_PARTS, (self.over, self.away), strict=True))


@dataclass(frozen=True, kw_only=True)
class RunRow(JsonRow):
    """One run on its fold's test examples."""

    run: str
    label: str                        # the variant's Table 2 name (display only)
    variant: dict[str, Any]           # the trainer's Variant.to_dict()
    fold: int
    test_set: str
    metrics: SetMetrics
    references: dict[str, Metrics]    # each reference's "all" metrics, by its name
    gain: Gain
    intervals: Intervals | None = since_version()    # 1.2; None where the run keeps none
    lump: LumpRow | None = written_if_set()           # 1.4: with a lump


@dataclass(frozen=True, kw_only=True)
class PooledRow(JsonRow):
    """One variant on one test set, its runs pooled over their folds."""

    label: str
    variant: dict[str, Any]
    test_set: str
    folds: int
    fold_ids: list[int]
    metrics: SetMetrics
    fold_ld_mean_sd_mm: float         # the spread of the folds' mean L_d
    references: dict[str, Metrics]
    gain: Gain
    folds_not_beating_references: list[int]
    intervals: Intervals | None = since_version()
    lump: LumpRow | None = written_if_set()


Row = RunRow | PooledRow


@dataclass(frozen=True, kw_only=True)
class ScarcityShares(JsonRow):
    """A scarcity model's shares of test points and examples inside its 90 % intervals (1.3;
    a model's row has both, each None where it keeps none) and the range each falls in by
    chance (1.5; None unless measured)."""

    points_90: float | None
    force_90: float | None
    points_90_low: float | None = None
    points_90_high: float | None = None
    force_90_low: float | None = None
    force_90_high: float | None = None

    def by_score(self) -> dict[str, tuple[float | None, list[float] | None]]:
        """Per score ('points', 'force'): its share and its band [low, high] (or None)."""
        return {"points": (self.points_90, _pair(self.points_90_low, self.points_90_high)),
                "force": (self.force_90, _pair(self.force_90_low, self.force_90_high))}


def _pair(low: float | None, high: float | None) -> list[float] | None:
    return None if low is None or high is None else [low, high]


@dataclass(frozen=True, kw_only=True)
class ScarcityRow(JsonRow):
    """One predictor of the data-scarcity study, trained (or fitted) on ``groups`` training
    groups of a fold; a model's row has its :class:`ScarcityShares`, a reference's none."""

    fold: int
    groups: int
    predictor: str
    ld_mean_mm: float | None
    ld_max_mm: float | None
    force_abs_n: float
    shares: ScarcityShares | None = flattened()


@dataclass(frozen=True, kw_only=True)
class Scores(JsonRow):
    """The document's tables: what ``pipeline eval`` scored."""

    runs: list[RunRow]
    overall: list[PooledRow]
    scarcity: list[ScarcityRow] | None = written_if_set()

    def to_doc(self, provenance: dict[str, Any]) -> dict[str, Any]:
        """The whole document: schema, the tables, and their ``provenance``."""
        return {"schema": METRICS.name, "schema_version": METRICS.version, **self.to_json(),
                "provenance": provenance}


_TABLES = Scores.kinds()
ROW_TABLES = tuple(k for k in _TABLES if k not in Scores.optional())   # runs, overall
METRICS = JsonSchema("phantom.metrics", "1.6", {
    "schema": str, "schema_version": str, **{k: _TABLES[k] for k in ROW_TABLES},
    "provenance": dict,
})
METRICS_OPTIONAL = {k: _TABLES[k] for k in Scores.optional()}
ROW_TYPES: dict[str, type[Row]] = dict(zip(ROW_TABLES, (RunRow, PooledRow), strict=True))
# Where a network reads each point's offsets from the tip: nowhere (the paper's network), in
# its first graph layer (tip offsets: every graph layer then reads the press), in its heads
OFFSETS = ("none", "graph", "heads")
METRIC_KEYS = Metrics.keys()
LD_KEYS = tuple(k for k, kind in Metrics.kinds().items()     # None: moves no point
                if isinstance(kind, tuple) and type(None) in kind)
METRIC_SETS = SetMetrics.keys()


def validate_metrics(path: str | Path) -> dict[str, Any]:
    """Read a ``phantom.metrics`` document of ``pipeline eval`` and check every field of it;
    return it.

    Every row has its keys with their types; every metric is a finite, non-negative
    number of plausible size for its unit (an error in micrometres written as millimetres is
    refused), and each set counts at least one example; each reference's metrics alike (L_d
    null for a reference that moves no point); each gain names a reference of its row and is
    at most 1 (a model error below zero); a variant is its fields, recursively through the
    run it was fine-tuned from; the fold lists name folds of the row.
    """
    doc = load_json(path)
    if isinstance(doc, dict) and "schema" not in doc and set(ROW_TABLES) <= set(doc):
        raise BadInput(path, "a metrics document from before phantom.metrics 1.0 (no schema): "
                             "re-run `pipeline eval`")
    doc = validate_json_doc(path, METRICS)
    typed_keys(path, doc, {**METRICS.keys, **METRICS_OPTIONAL}, "the document",
               optional=METRICS_OPTIONAL)
    for table, row_type in ROW_TYPES.items():
        for i, row in enumerate(doc[table]):
            _check_row(path, row, row_type, f"{table}[{i}]")
    shares = ScarcityShares.keys()
    for i, row in enumerate(doc.get("scarcity", [])):
        where, kinds = f"scarcity[{i}]", ScarcityRow.kinds()
        typed_keys(path, row, kinds, where, optional=shares)
        if any(k in row for k in shares):     # a model's row: both of its shares (null or not)
            typed_keys(path, row, ScarcityShares.kinds(), where,
                       optional=ScarcityShares.optional())
        check_numbers(path, {k: row[k] for k, kind in kinds.items()    # a reference may
                             if k not in shares and kind is not str    # have no L_d
                             and row[k] is not None}, where)
        check_shares(path, row, shares, where)
    return doc


def _check_row(path: str | Path, row: Any, row_type: type[Row], where: str) -> None:
    """One row of ``runs`` or ``overall``: its keys, metrics, references, gain, variant and
    (1.2) intervals."""
    typed_keys(path, row, row_type.kinds(), where, optional=row_type.optional())
    if row.get("intervals") is not None:
        check_intervals(path, row["intervals"], f"{where}.intervals")
    if "lump" in row:
        _check_lump(path, row["lump"], set(row["references"]), f"{where}.lump")
    _check_metric_sets(path, row["metrics"], f"{where}.metrics")
    if not row["references"]:
        raise BadInput(path, f"{where}.references is empty")
    strange = sorted(set(row["references"]) - set(REFERENCES))
    if strange:
        raise BadInput(path, f"{where}.references names no reference: {strange} (they are "
                             f"{list(REFERENCES)})")
    for name, values in row["references"].items():
        _check_metric_values(path, values, f"{where}.references[{name!r}]", null_ld=True)
    _check_gain(path, row["gain"], set(row["references"]), f"{where}.gain")
    _check_variant(path, row["variant"], f"{where}.variant")
    if "fold_ids" in row:
        _check_folds(path, row, where)


def _check_lump(path: str | Path, lump: dict, references: set[str], where: str) -> None:
    """A row's lump: its place, and each part's metrics, references, gain and intervals."""
    typed_keys(path, lump, LumpRow.kinds(), where)
    for part in ("over", "away"):
        got, at = lump[part], f"{where}.{part}"
        if got is None:
            continue
        typed_keys(path, got, LumpPart.kinds(), at)
        _check_metric_values(path, got["metrics"], f"{at}.metrics")
        for name, values in got["references"].items():
            _check_metric_values(path, values, f"{at}.references[{name!r}]", null_ld=True)
        _check_gain(path, got["gain"], references, f"{at}.gain")
        if got["intervals"] is not None:
            check_intervals(path, got["intervals"], f"{at}.intervals")


def _check_gain(path: str | Path, gain: dict, references: set[str], where: str) -> None:
    """The best reference of L_d and of force (one of the row's, or null) and the gain over
    it: at most 1 (the model's error is not below zero), null where either is missing."""
    kinds = Gain.kinds()
    typed_keys(path, gain, kinds, where)
    for what in ("ld", "force"):
        name = gain[f"{what}_reference"]
        if name is not None and name not in references:
            raise BadInput(path, f"{where}.{what}_reference {name!r} is not one of the row's "
                                 "references")
        value = gain[f"{what}_gain"]
        if value is not None and not (math.isfinite(value) and value <= 1):
            raise BadInput(path, f"{where}.{what}_gain is {value!r}: not a finite number "
                                 "<= 1")
    check_numbers(path, {k: gain[k] for k in kinds if k.endswith(("_mm", "_n"))
                         and gain[k] is not None}, where)


def _check_variant(path: str | Path, variant: Any, where: str) -> None:
    """A run's variant: model, training data, rotation, aug, and the variant it was
    fine-tuned from (null, or a variant)."""
    typed_keys(path, variant, VariantRow.kinds(), where, optional=VariantRow.optional())
    if variant.get("offsets", "none") not in OFFSETS:
        raise BadInput(path, f"{where}.offsets is {variant['offsets']!r}, not one of "
                             f"{list(OFFSETS)}")
    if variant["pretrained"] is not None:
        _check_variant(path, variant["pretrained"], f"{where}.pretrained")


def _check_folds(path: str | Path, row: dict, where: str) -> None:
    """``fold_ids``: one per fold pooled; the folds not beating the references among them."""
    ids, worse = row["fold_ids"], row["folds_not_beating_references"]
    if not (int_list(ids) and int_list(worse)):
        raise BadInput(path, f"{where}: fold_ids and folds_not_beating_references must be "
                             "lists of integers")
    if len(ids) != row["folds"] or not set(worse) <= set(ids):
        raise BadInput(path, f"{where}: fold_ids must list its {row['folds']} folds, and "
                             "folds_not_beating_references only folds of them")
    check_numbers(path, {"fold_ld_mean_sd_mm": row["fold_ld_mean_sd_mm"]}, where)


def _check_metric_sets(path: str | Path, metrics: dict, where: str) -> None:
    if "all" not in metrics or set(metrics) - set(METRIC_SETS):
        raise BadInput(path, f"{where} must hold 'all' and only {METRIC_SETS}")
    for name, values in metrics.items():
        _check_metric_values(path, values, f"{where}.{name}")


def _check_metric_values(path: str | Path, values: Any, where: str,
                         null_ld: bool = False) -> None:
    """One set's metrics: :data:`METRIC_KEYS`, ``n`` at least 1, the rest finite and
    plausible (with ``null_ld``, the L_d values may be null: a predictor moving no point)."""
    if not isinstance(values, dict) or not isinstance(values.get("n"), int) or \
            isinstance(values["n"], bool) or values["n"] < 1:
        raise BadInput(path, f"{where}.n must count at least one example")
    if not set(METRIC_KEYS) <= set(values):
        raise BadInput(path, f"{where} lacks {sorted(set(METRIC_KEYS) - set(values))}")
    check_numbers(path, {k: v for k, v in values.items()
                         if not (null_ld and k in LD_KEYS and v is None)}, where)

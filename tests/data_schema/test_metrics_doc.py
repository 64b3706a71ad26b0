"""The ``phantom.metrics`` document (``pipeline eval --out``): every field is checked,
``references`` and ``gain`` among them."""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path
from typing import Any

import pytest

from core.errors import BadInput
from data_schema.metrics_doc import METRICS, Scores, beats, validate_metrics


def _values(ld: float | None = 0.3) -> dict[str, Any]:
    return {"n": 4, "force_mse_n2": 0.1, "force_abs_n": 0.2, "force_abs_sd_n": 0.1,
            "ld_mean_mm": ld, "ld_mean_sd_mm": None if ld is None else 0.1,
            "ld_max_mm": None if ld is None else 0.9, "ld_max_sd_mm": None if ld is None else 0.2}


VARIANT = {"model": "cGNN", "train_data": "Exp", "rotate": True, "aug": False,
           "pretrained": {"model": "cGNN", "train_data": "MSM", "rotate": True, "aug": False,
                          "pretrained": None}}
REFERENCES = {"nothing moves": _values(0.5), "nearest press": _values(0.4),
              "force, linear": _values(None)}
GAIN = {"ld_reference": "nearest press", "ld_reference_mm": 0.4, "ld_gain": 0.25,
        "force_reference": "force, linear", "force_reference_n": 0.2, "force_gain": -0.5}


def _doc() -> dict[str, Any]:
    row = {"label": "cGNN/MSM (TL)", "variant": VARIANT, "test_set": "Exp",
           "metrics": {"single": _values(), "all": _values()}, "references": REFERENCES,
           "gain": GAIN}
    return {"schema": METRICS.name, "schema_version": METRICS.version,
            "runs": [{**row, "run": "runs/a", "fold": 0}],
            "overall": [{**row, "folds": 2, "fold_ids": [0, 1], "fold_ld_mean_sd_mm": 0.01,
                         "folds_not_beating_references": [1]}],
            "scarcity": [{"fold": 0, "groups": 1, "predictor": "force, linear",
                          "ld_mean_mm": None, "ld_max_mm": None, "force_abs_n": 0.3}],
            "provenance": {"stage": "eval"}}


def _write(tmp_path: Path, doc: dict) -> Path:
    path = tmp_path / "metrics.json"
    path.write_text(json.dumps(doc))
    return path


def test_a_whole_document_is_valid(tmp_path) -> None:
    assert validate_metrics(_write(tmp_path, _doc()))["schema"] == "phantom.metrics"


def _set(doc: dict, keys: tuple, value: Any) -> dict:
    doc = copy.deepcopy(doc)
    obj = doc
    for k in keys[:-1]:
        obj = obj[k]
    if value is _DROP:
        del obj[keys[-1]]
    else:
        obj[keys[-1]] = value
    return doc


_DROP = object()
CASES = [
    (("runs", 0, "references"), _DROP, "runs[0].references missing"),
    (("overall", 0, "references"), [], "overall[0].references missing"),
    (("runs", 0, "references"), {}, "references is empty"),
    (("runs", 0, "references", "a guess"), _values(), "names no reference: ['a guess']"),
    (("runs", 0, "references", "nearest press", "force_abs_n"), float("nan"), "not a finite"),
    (("runs", 0, "references", "nothing moves", "n"), 0, "at least one example"),
    (("runs", 0, "references", "nothing moves", "ld_mean_mm"), _DROP, "lacks"),
    (("runs", 0, "references", "nothing moves", "force_abs_n"), None, "not a finite"),
    (("runs", 0, "gain"), _DROP, "runs[0].gain missing"),
    (("overall", 0, "gain"), "0.25", "overall[0].gain missing"),
    (("runs", 0, "gain", "ld_gain"), _DROP, "gain.ld_gain missing"),
    (("runs", 0, "gain", "ld_gain"), "0.25", "gain.ld_gain missing"),
    (("runs", 0, "gain", "ld_gain"), 1.5, "<= 1"),
    (("runs", 0, "gain", "force_reference"), "a guess", "not one of the row's references"),
    (("runs", 0, "gain", "ld_reference_mm"), -1.0, "not a finite"),
    (("runs", 0, "variant", "rotate"), "yes", "variant.rotate"),
    (("runs", 0, "variant", "pretrained", "model"), _DROP, "variant.pretrained.model"),
    (("runs", 0, "variant", "offsets"), "tip", "variant.offsets is 'tip', not one of"),
    (("runs", 0, "variant", "pretrained", "offsets"), 1, "variant.pretrained.offsets missing"),
    (("overall", 0, "fold_ids"), [0], "fold_ids must list"),
    (("overall", 0, "folds_not_beating_references"), [3], "only folds of them"),
    (("scarcity", 0, "force_abs_n"), None, "scarcity[0].force_abs_n"),
    (("scarcity", 0), {**_doc()["scarcity"][0], "points_90": 0.9, "force_90": 0.9,
                       "force_90_high": 1.5}, "force_90_high is 1.5: not in [0, 1]"),
    (("provenance",), _DROP, "'provenance' missing"),
    (("schema_version",), "2.0", "not compatible"),
    (("schema",), "phantom.folds", "not a phantom.metrics document"),
]


@pytest.mark.parametrize(("keys", "value", "words"), CASES,
                         ids=[".".join(map(str, k)) + f"={'dropped' if v is _DROP else v!r}"
                              for k, v, _ in CASES])
def test_a_wrong_field_is_refused_by_name(tmp_path, keys, value, words) -> None:
    with pytest.raises(BadInput, match=words.replace("[", r"\[").replace("]", r"\]")):
        validate_metrics(_write(tmp_path, _set(_doc(), keys, value)))


def test_where_the_network_reads_the_offsets_is_valid_and_may_be_absent(tmp_path) -> None:
    """1.1 records where a network reads the tip's offsets; a 1.0 variant has no such field
    (the fixture's) and stays valid."""
    for where in ("none", "graph", "heads"):
        doc = _set(_doc(), ("runs", 0, "variant", "offsets"), where)
        doc = _set(doc, ("runs", 0, "variant", "pretrained", "offsets"), where)
        validate_metrics(_write(tmp_path, doc))
    assert "offsets" not in _doc()["runs"][0]["variant"]


def test_a_document_from_before_the_schema_says_so(tmp_path) -> None:
    doc = {k: v for k, v in _doc().items() if k not in ("schema", "schema_version")}
    with pytest.raises(BadInput, match="before phantom.metrics 1.0"):
        validate_metrics(_write(tmp_path, doc))


def test_a_key_added_by_hand_is_left_alone(tmp_path) -> None:
    doc = _set(_set(_doc(), ("comment",), "by hand"), ("runs", 0, "note"), "x")
    validate_metrics(_write(tmp_path, doc))


def _intervals() -> dict[str, Any]:
    level = {"level": 0.9, "points": 100, "coverage": 0.9, "mean_radius_mm": 0.3,
             "examples": 10, "force_coverage": 0.9, "force_half_width_n": 0.1}
    return {"levels": [level], "radius_to_ld": 2.0, "calibration": {"presses": 3, "examples": 9},
            "by_distance": [{"from_mm": 40.0, "to_mm": None, "points": 5, "coverage": 1.0,
                             "mean_radius_mm": None}]}


INTERVAL_CASES = [
    (("levels", 0, "coverage"), 1.2, "coverage is 1.2: not in [0, 1]"),
    (("levels", 0, "level"), 1.0, "level is 1.0: not in (0, 1)"),
    (("levels", 0, "mean_radius_mm"), 300.0, "more than a plausible"),
    (("levels", 0, "points"), 0, "at least one point"),
    (("by_distance", 0, "force_coverage"), 0.5, None),        # a key added by hand
    (("calibration", "presses"), "3", "calibration.presses"),
    (("radius_to_ld",), _DROP, "radius_to_ld missing"),
    (("levels", 0, "band"), [0.85, 0.95], None),                # 1.5: the range by chance
    (("levels", 0, "band"), [0.95, 0.85], "band is [0.95, 0.85]: not a [low, high] pair"),
    (("levels", 0, "force_band"), [0.9], "force_band is [0.9]: not a [low, high] pair"),
    (("levels", 0, "force_band"), [0.8, 1.2], "not a [low, high] pair of shares"),
    (("levels", 0, "band"), "0.9", "band missing or not of type"),
]


@pytest.mark.parametrize(("keys", "value", "words"), INTERVAL_CASES)
def test_intervals_are_checked_and_may_be_absent(tmp_path, keys, value, words) -> None:
    """1.2: a row's intervals are checked field by field; null (a run that keeps none) and a
    1.1 document without them stay valid."""
    doc = _set(_doc(), ("runs", 0, "intervals"), _set(_intervals(), keys, value))
    if words is None:
        validate_metrics(_write(tmp_path, doc))
    else:
        with pytest.raises(BadInput, match=re.escape(words)):
            validate_metrics(_write(tmp_path, doc))
    validate_metrics(_write(tmp_path, _set(_doc(), ("overall", 0, "intervals"), None)))
    validate_metrics(_write(tmp_path, _set(_doc(), ("schema_version",), "1.1")))


WRITTEN = {"runs": ("run", "label", "variant", "fold", "test_set", "metrics", "references",
                    "gain", "intervals", "lump"),
           "overall": ("label", "variant", "test_set", "folds", "fold_ids", "metrics",
                       "fold_ld_mean_sd_mm", "references", "gain",
                       "folds_not_beating_references", "intervals")}


def _full_doc() -> dict[str, Any]:
    """The fixture with every later field: intervals on a run (with its calibration, bands
    and the tip's point) and none on the pooled row, a lump with one part empty, and a
    model's scarcity row beside a reference's."""
    doc = _doc()
    given = _intervals()
    given["levels"][0] |= {"band": [0.85, 0.95], "force_band": [0.8, 1.0]}
    given["tip_point"] = {"from_mm": 0.0, "to_mm": 0.1, "points": 2, "coverage": 0.5,
                          "mean_radius_mm": 0.2}
    intervals = {k: given[k] for k in ("levels", "by_distance", "radius_to_ld", "tip_point",
                                       "calibration")}
    part = {"metrics": _values(), "references": REFERENCES, "gain": GAIN, "intervals": None}
    doc["runs"][0] |= {"intervals": intervals,
                       "lump": {"centre_mm": [50.0, 40.0], "radius_mm": 12.0,
                                "reach_mm": 10.0, "over": part, "away": None}}
    doc["overall"][0]["intervals"] = None
    for table, order in WRITTEN.items():          # the order eval writes them in
        doc[table] = [{k: row[k] for k in order} for row in doc[table]]
    doc["scarcity"].insert(0, {"fold": 0, "groups": 1, "predictor": "TL", "ld_mean_mm": 0.3,
                               "ld_max_mm": 0.9, "force_abs_n": 0.2, "points_90": 0.9,
                               "force_90": None, "points_90_low": 0.8,
                               "points_90_high": 0.95, "force_90_low": None,
                               "force_90_high": None})
    return doc


def test_the_rows_read_and_write_the_document_as_it_is(tmp_path) -> None:
    """A valid document read into its rows and written back is the same text, key for key
    and in order; a row's fields are its keys."""
    doc = _full_doc()
    validate_metrics(_write(tmp_path, doc))
    scores = Scores.from_json(doc)
    assert json.dumps(scores.to_doc(doc["provenance"])) == json.dumps(doc)
    run = scores.runs[0]
    assert run.metrics.all.ld_mean_mm == 0.3 and run.metrics.multi is None
    assert run.references["force, linear"].ld_mean_mm is None
    assert run.gain.force_reference == "force, linear" and run.lump.away is None
    assert run.intervals.at(0.9).band == [0.85, 0.95] and run.intervals.calibration.presses == 3
    model, reference = scores.scarcity
    assert model.shares.by_score() == {"points": (0.9, [0.8, 0.95]), "force": (None, None)}
    assert reference.shares is None


SHARE_ROWS = {                            # a scarcity row's shares: what eval may write, and not
    "a reference's (none)": ({}, True),
    "a model's": ({"points_90": 0.9, "force_90": 0.85}, True),
    "a model's without intervals (both null)": ({"points_90": None, "force_90": None}, True),
    "a model's with its bands (1.5)": ({"points_90": 0.9, "force_90": 0.85,
                                        "points_90_low": 0.8, "points_90_high": 0.95}, True),
    "the points' share alone": ({"points_90": 0.9}, False),
    "the force's share alone": ({"force_90": 0.9}, False),
    "a band alone": ({"points_90_low": 0.8, "points_90_high": 0.95}, False),
}


@pytest.mark.parametrize(("shares", "valid"), SHARE_ROWS.values(), ids=list(SHARE_ROWS))
def test_a_scarcity_row_is_valid_exactly_where_its_row_reads(tmp_path, shares, valid) -> None:
    """A model's row has both shares (each may be null), a reference's none: what the check
    accepts reads into its row, and a row with one share and not the other is refused by
    name rather than read as a crash."""
    doc = _doc()
    doc["scarcity"][0] |= shares
    if valid:
        validate_metrics(_write(tmp_path, doc))
        row = Scores.from_json(doc).scarcity[0]
        assert (row.shares is None) == (not shares)
    else:
        missing = next(k for k in ("points_90", "force_90") if k not in shares)
        with pytest.raises(BadInput, match=re.escape(f"scarcity[0].{missing} missing")):
            validate_metrics(_write(tmp_path, doc))
        with pytest.raises(TypeError):      # what the check keeps from the reader
            Scores.from_json(doc)


def test_a_gain_beats_the_references_only_above_zero() -> None:
    """What ``eval --strict`` and the pooled rows' ``folds_not_beating_references`` count: a
    gain is one above zero; none at zero, below it, or where there is no gain (not finite)."""
    assert beats(0.01) and beats(1.0)
    assert not beats(0.0) and not beats(-0.2) and not beats(None)

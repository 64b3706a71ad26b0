"""JSON manifests: fold lists and fit-msm parameters are checked on write and by inspect."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from core.errors import BadInput
from data_schema.json_docs import MSM_PARAMS, validate_folds, validate_json_doc
from pipeline.cli import cli


def _folds_doc() -> dict:
    role = lambda groups, single: {"groups": groups, "single": single, "multi": []}  # noqa: E731
    return {"schema": "phantom.folds", "schema_version": "2.0",
            "data": {"file": "states.h5", "sha256": "0" * 64}, "group_by": "sequence",
            "ratio": [2, 1, 1], "seed": 0, "groups": 4, "note": "", "provenance": {},
            "folds": [{"fold": 0, "train": role([0, 1], [0, 1]), "val": role([2], [2]),
                       "test": role([3], [3]), "train_subsets": [[1], [1, 0]]}]}


def test_folds_manifest_is_checked(tmp_path):
    good = tmp_path / "splits.json"
    good.write_text(json.dumps(_folds_doc()))
    assert len(validate_folds(good)["folds"]) == 1
    res = CliRunner().invoke(cli, ["inspect", str(good), "--json"])
    s = json.loads(res.output)
    assert s["schema"] == "phantom.folds" and s["details"]["valid"] == "valid"
    assert s["details"]["folds"][0] == {"train": 2, "val": 1, "test": 1}
    leaky = tmp_path / "leaky.json"
    doc = _folds_doc()
    doc["folds"][0]["val"]["single"] = [1]
    leaky.write_text(json.dumps(doc))
    with pytest.raises(BadInput, match="fold 0"):
        validate_folds(leaky)
    assert "invalid" in json.loads(CliRunner().invoke(
        cli, ["inspect", str(leaky), "--json"]).output)["details"]["valid"]
    doc = _folds_doc()
    doc["folds"][0]["train_subsets"] = [[1], [2, 1]]        # a subset beyond the training groups
    leaky.write_text(json.dumps(doc))
    with pytest.raises(BadInput, match="train subset 2"):
        validate_folds(leaky)
    old = tmp_path / "old.json"
    old.write_text(json.dumps([{"train": [0], "val": [1]}]))
    with pytest.raises(BadInput, match="re-run `pipeline split`"):
        validate_folds(old)


def test_msm_params_document(tmp_path):
    doc = {"schema": MSM_PARAMS.name, "schema_version": "1.0", "k_between": 100.0,
           "k_fixed": 21.0, "mean_distance_m": 1e-4, "msm_params": {}, "provenance": {}}
    p = tmp_path / "params.json"
    p.write_text(json.dumps(doc))
    assert validate_json_doc(p, MSM_PARAMS)["k_fixed"] == 21.0
    p.write_text(json.dumps({**doc, "k_fixed": "21"}))
    with pytest.raises(BadInput, match="k_fixed"):
        validate_json_doc(p, MSM_PARAMS)

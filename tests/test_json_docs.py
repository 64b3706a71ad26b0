"""JSON manifests: fold lists and fit-msm parameters are checked on write and by inspect."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from core.errors import BadInput
from data_schema.json_docs import MSM_PARAMS, validate_folds, validate_json_doc
from pipeline.cli import cli


def test_folds_manifest_is_checked(tmp_path):
    good = tmp_path / "splits.json"
    good.write_text(json.dumps([{"train": [0, 1], "val": [2], "test": [3]},
                                {"train": [1, 2], "val": [3]}]))
    assert len(validate_folds(good)) == 2
    res = CliRunner().invoke(cli, ["inspect", str(good), "--json"])
    s = json.loads(res.output)
    assert s["schema"] == "phantom.folds" and s["details"]["valid"] == "valid"
    assert s["details"]["folds"][0] == {"train": 2, "val": 1, "test": 1}
    leaky = tmp_path / "leaky.json"
    leaky.write_text(json.dumps([{"train": [0, 1], "val": [1]}]))
    with pytest.raises(BadInput, match="fold 0"):
        validate_folds(leaky)
    assert "invalid" in json.loads(CliRunner().invoke(
        cli, ["inspect", str(leaky), "--json"]).output)["details"]["valid"]


def test_msm_params_document(tmp_path):
    doc = {"schema": MSM_PARAMS.name, "schema_version": "1.0", "k_between": 100.0,
           "k_fixed": 21.0, "mean_distance_m": 1e-4, "msm_params": {}, "provenance": {}}
    p = tmp_path / "params.json"
    p.write_text(json.dumps(doc))
    assert validate_json_doc(p, MSM_PARAMS)["k_fixed"] == 21.0
    p.write_text(json.dumps({**doc, "k_fixed": "21"}))
    with pytest.raises(BadInput, match="k_fixed"):
        validate_json_doc(p, MSM_PARAMS)

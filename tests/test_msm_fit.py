"""`pipeline fit-msm`: recovers known spring constants from states the MSM itself produced."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from pipeline.cli import cli
from sim.msm import MSMParams
from sim.msm_dataset import Plan, Protocol, draw_plan, file_attrs, generate, write_states
from sim.msm_fit import fit_msm, mean_distance, read_measured

TRUE = MSMParams(k_between=80.0, k_fixed=30.0)
PROTOCOL = Protocol(locations=2, directions=1, steps=4, fmax=6.0, seed=5)


@pytest.fixture(scope="module")
def made(tmp_path_factory) -> tuple[Path, dict]:
    """States the MSM produced with k_between = 80, k_fixed = 30 N/m."""
    out = tmp_path_factory.mktemp("fit") / "msm80.h5"
    _, arrays = generate(out, PROTOCOL, TRUE)
    return out, arrays


def test_recovers_known_constants_within_2_percent(made):
    sequences, params = read_measured(made[0])
    assert (params.k_between, params.k_fixed) == (80.0, 30.0)    # the grid it was made with
    result = fit_msm(sequences, params, start=(100.0, 21.0))
    assert result.k_between == pytest.approx(80.0, rel=0.02)
    assert result.k_fixed == pytest.approx(30.0, rel=0.02)
    assert result.mean_distance_m < 1e-6 < result.start_distance_m
    assert result.states == 8


def test_mean_distance_is_zero_only_at_the_truth(made):
    sequences, params = read_measured(made[0])
    assert mean_distance(params, sequences) < 1e-7             # float32 storage only
    assert mean_distance(MSMParams(k_between=88.0, k_fixed=30.0), sequences) > 1e-6


def test_lab_like_states_in_another_frame(made, tmp_path):
    """4 x 4 markers plus the tip, shifted and lifted into a lab frame: found again."""
    _, a = made
    keep = [i * 32 + j for i in (3, 11, 20, 28) for j in (3, 11, 20, 28)]
    shift = np.array([0.31, -0.12, 0.85], np.float32)
    pts = np.concatenate([a["states/points"][:, keep], a["states/tip"][:, None]], axis=1)
    lab = {**a, "states/points": pts + shift, "states/tip": a["states/tip"] + shift}
    path = tmp_path / "lab.h5"
    attrs = file_attrs(_plan(), TRUE, 1e-6, {"stage": "test"}, None)
    attrs.update(source="lab")
    del attrs["msm_params"]
    write_states(path, lab, attrs)
    sequences, params = read_measured(path)
    assert params == MSMParams()                              # lab: the paper's grid
    assert sequences[0].masses.tolist() == [*keep, sequences[0].node]
    result = fit_msm(sequences, params, start=(100.0, 21.0))
    assert result.k_between == pytest.approx(80.0, rel=0.02)
    assert result.k_fixed == pytest.approx(30.0, rel=0.02)


def _plan() -> Plan:
    return draw_plan(PROTOCOL, 1024)


def test_cli_writes_the_constants(made, tmp_path):
    out = tmp_path / "params.json"
    result = CliRunner().invoke(cli, ["fit-msm", str(made[0]), "--out", str(out),
                                      "--max-sequences", "1"])
    assert result.exit_code == 0, result.output
    record = json.loads(out.read_text())
    assert record["k_between"] == pytest.approx(80.0, rel=0.02)
    assert record["msm_params"]["k_fixed"] == pytest.approx(30.0, rel=0.02)
    assert str(made[0]) in record["provenance"]["inputs"] and record["sequences"] == 1
    assert "k_between 80" in result.output


def test_cli_bad_input(tmp_path):
    bad = tmp_path / "bad.h5"
    bad.write_text("not hdf5")
    out = tmp_path / "params.json"
    result = CliRunner().invoke(cli, ["fit-msm", str(bad), "--out", str(out)])
    assert result.exit_code == 2 and result.output.startswith("error:")
    assert str(bad) in result.output and not out.exists()
    nors = tmp_path / "norest.h5"
    _, a = generate(tmp_path / "src.h5", Protocol(locations=1, directions=1, steps=2), TRUE)
    keep = a["states/step"] > 0
    cut = {k: (v[keep] if k.startswith("states/") else v[:0]) for k, v in a.items()}
    attrs = file_attrs(_plan(), TRUE, 1e-6, {"stage": "test"}, None)
    write_states(nors, cut, attrs)
    result = CliRunner().invoke(cli, ["fit-msm", str(nors)])
    assert result.exit_code == 2 and "no rest state" in result.output

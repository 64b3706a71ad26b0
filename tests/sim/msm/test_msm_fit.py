"""`pipeline fit-msm`: recovers known spring constants from states the MSM itself produced."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from core.errors import BadInput
from core.recording import rrd_entities
from pipeline.cli import cli
from sim.msm import msm_fit
from sim.msm.msm import MSMError, MSMParams
from sim.msm.msm_dataset import file_attrs, write_states
from sim.msm.msm_fit import fit_msm, mean_distance, still
from sim.msm.msm_measured import read_measured
from sim.msm.msm_protocol import Plan, Protocol, draw_plan
from sim.msm.simulate_stage import generate

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


def _twin_layout() -> np.ndarray:
    """The twin's markers in the phantom frame: 5 x 5 at 20 mm pitch about the centre, not on
    the masses (the pitch is 6.2 mass spacings), one corner lost."""
    pitch = 0.05 + 0.020 * (np.arange(5) - 2)
    xy = np.array([(x, y) for y in pitch for x in pitch])[1:]
    return np.c_[xy, np.zeros(len(xy))]


def _lab_file(path: Path, params: MSMParams, radius: float = 0.0) -> Path:
    """Lab states as extract writes them, made by the MSM: markers laid out like the twin's,
    the tip last, normal presses inside the markers' footprint, no force vectors (a lab's
    Nano17 force stays in the sensor frame: only the magnitude reaches the states)."""
    protocol = Protocol(locations=3, directions=1, steps=4, fmax=6.0, seed=3,
                        contact_radius=radius)
    _, arrays = generate(path.with_suffix(".msm.h5"), protocol, params, layout=_twin_layout())
    lab = {k: v for k, v in arrays.items() if k not in ("states/force_vector", "states/mass")}
    attrs = file_attrs(draw_plan(protocol, 1024), params, 1e-6, {"stage": "test"}, None)
    attrs.update(source="lab")
    del attrs["msm_params"], attrs["protocol"]
    write_states(path, lab, attrs)
    return path


def test_lab_states_land_where_they_are_pushed_into_the_surface(tmp_path):
    """The regression: lab states were placed upside down (the MSM pushed up while the phantom
    was pushed down), so every constant looked worse than a still surface."""
    sequences, params = read_measured(_lab_file(tmp_path / "lab.h5", TRUE))
    assert params == MSMParams()                              # lab: the paper's grid
    first = sequences[0]
    assert first.is_tip.tolist() == [False] * 24 + [True]    # the tip is the last point
    assert (first.forces[:, 2] < -0.99 * np.linalg.norm(first.forces, axis=1)).all()
    truth = replace(params, k_between=80.0, k_fixed=30.0)
    assert mean_distance(truth, sequences) < 1e-6 < still(sequences, True).pooled


@pytest.mark.parametrize("radius", [0.0, 0.004])
def test_lab_states_give_the_constants(tmp_path, radius):
    sequences, params = read_measured(_lab_file(tmp_path / "lab.h5", TRUE, radius),
                                      contact_radius=radius)
    assert len(sequences[0].contact) == (1 if radius == 0 else 5)
    result = fit_msm(sequences, params, start=(100.0, 21.0), rel_tol=1e-3)
    assert result.k_between == pytest.approx(80.0, rel=0.02)
    assert result.k_fixed == pytest.approx(30.0, rel=0.02)
    assert result.mean_distance_m < 0.01 * result.still_distance_m
    assert result.at_bound == []


def test_a_marker_missing_at_rest_is_left_out_not_an_index(tmp_path):
    """A NaN rest position becomes no grid index: that marker is left out of the distance and
    the rest still fits."""
    path = _lab_file(tmp_path / "lab.h5", TRUE)
    with h5py.File(path, "r+") as f:
        points, valid = f["states/points"][()], f["states/valid"][()]
        points[0, 3], valid[0, 3] = np.nan, False
        f["states/points"][...], f["states/valid"][...] = points, valid
    sequences, params = read_measured(path)
    assert mean_distance(replace(params, k_between=80.0, k_fixed=30.0), sequences) < 1e-6


def test_the_tip_missing_at_rest_is_one_line(tmp_path):
    path = _lab_file(tmp_path / "lab.h5", TRUE)
    with h5py.File(path, "r+") as f:
        tip = f["states/tip"][()]
        tip[0] = np.nan
        f["states/tip"][...] = tip
    result = CliRunner().invoke(cli, ["fit-msm", str(path), "--workers", "1"])
    assert result.exit_code == 2 and len(result.output.splitlines()) == 1, result.output
    assert str(path) in result.output


def _plan() -> Plan:
    return draw_plan(PROTOCOL, 1024)


def test_cli_writes_the_constants_the_references_and_a_recording(made, tmp_path):
    out = tmp_path / "params.json"
    result = CliRunner().invoke(cli, ["fit-msm", str(made[0]), "--out", str(out),
                                      "--max-sequences", "1", "--workers", "1"])
    assert result.exit_code == 0, result.output
    record = json.loads(out.read_text())
    assert record["k_between"] == pytest.approx(80.0, rel=0.02)
    assert record["msm_params"]["k_fixed"] == pytest.approx(30.0, rel=0.02)
    assert str(made[0]) in record["provenance"]["inputs"] and record["sequences"] == 1
    assert record["still_distance_m"] > 100 * record["mean_distance_m"]
    assert len(record["per_sequence"]) == 1
    assert result.output.startswith("k_between 79.") or result.output.startswith("k_between 80")
    assert "still surface" in result.output
    entities = set(rrd_entities(out.with_suffix(".rrd")))
    assert {"/distance/fitted", "/distance/still", "/distance/start"} <= entities
    assert any(e.endswith("/measured") for e in entities) and \
        any(e.endswith("/msm") for e in entities)


def test_cli_fits_a_fold_s_training_presses_only(tmp_path):
    path = _lab_file(tmp_path / "lab.h5", TRUE)
    splits = tmp_path / "splits.json"
    assert CliRunner().invoke(cli, ["split", str(path), "--out", str(splits), "--folds", "3",
                                    "--ratio", "1:1:1", "--no-rrd"]).exit_code == 0
    train = json.loads(splits.read_text())["folds"][1]["train"]["groups"]
    out = tmp_path / "fit.json"
    result = CliRunner().invoke(cli, ["fit-msm", str(path), "--splits", str(splits), "--fold",
                                      "1", "--out", str(out), "--no-rrd", "--workers", "1"])
    assert result.exit_code == 0, result.output
    assert [r["sequence"] for r in json.loads(out.read_text())["per_sequence"]] == train


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
    assert result.exit_code == 2 and "no sequence with a rest state" in result.output


def test_a_press_without_its_rest_state_is_left_out_with_a_warning(tmp_path, capsys):
    """Extract may leave a press's rest state out (the tip hidden there): that press is left
    out of the fit, said in one line, and the others are read (fit-msm reads them so)."""
    _, a = generate(tmp_path / "src.h5", Protocol(locations=3, directions=1, steps=2), TRUE)
    keep = ~((a["states/sequence"] == 1) & (a["states/step"] == 0))
    cut = {k: (v[keep] if k.startswith("states/") else v[:0]) for k, v in a.items()}
    write_states(tmp_path / "holed.h5", cut, file_attrs(_plan(), TRUE, 1e-6, {"stage": "test"},
                                                         None))
    sequences, _ = read_measured(tmp_path / "holed.h5")
    assert [s.sequence for s in sequences] == [0, 2]
    warned = capsys.readouterr().err.strip().splitlines()
    assert len(warned) == 1 and "sequence 1 has no rest state (step 0): left out" in warned[0]


def test_cli_refuses_a_start_outside_the_physical_range(made, tmp_path):
    """--start 1e6 1e-3 N/m (a stiffness ratio of 1e9; the MSM cannot settle there) ends at
    once with one line, no file, rather than searched from (hundreds of failing trials, a
    distance of Infinity): the command line refuses it as it parses, the fit when a library
    caller asks."""
    out = tmp_path / "params.json"
    result = CliRunner().invoke(cli, ["fit-msm", str(made[0]), "--out", str(out),
                                      "--max-sequences", "1", "--start", "1e6", "1e-3"])
    assert result.exit_code == 2, result.output
    assert result.output.startswith("error: --start ") and len(result.output.splitlines()) == 1
    assert "must be in [1, 100000] N/m" in result.output
    assert not out.exists()
    sequences, params = read_measured(made[0], max_sequences=1)
    with pytest.raises(BadInput, match=r"must lie in \[1, 100000\] N/m"):
        fit_msm(sequences, params, start=(1e6, 1e-3))


def test_a_fit_whose_every_trial_fails_is_refused(made, monkeypatch):
    def unsettled(*args, **kwargs):
        raise MSMError("static solve did not converge")

    sequences, params = read_measured(made[0])
    monkeypatch.setattr(msm_fit, "mean_distance", unsettled)
    with pytest.raises(BadInput, match="cannot settle"):
        fit_msm(sequences, params)

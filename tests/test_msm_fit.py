"""`pipeline fit-msm`: recovers known spring constants from states the MSM itself produced."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from core.errors import BadInput
from pipeline.cli import cli
from sim import msm_fit
from sim.msm import MSMError, MSMParams
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


def _rotation(yaw_deg: float, tilt_deg: float) -> np.ndarray:
    """Turned ``yaw_deg`` about z after tilting ``tilt_deg`` about x."""
    y, t = np.radians(yaw_deg), np.radians(tilt_deg)
    rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
    return rz @ rx


def _twin_layout() -> np.ndarray:
    """The twin's markers in the MSM grid frame: 5 x 5 at 20 mm pitch, one corner lost.

    Centred like the fit centres them (centroid on the grid centre). Not on the masses (the
    pitch is 6.2 mass spacings); without the lost corner the middle row would fall exactly
    between two masses, so the mass "nearest" it would be a tie.
    """
    pitch = 0.020 * (np.arange(5) - 2)
    xy = np.array([(x, y) for y in pitch for x in pitch])[1:]
    return np.c_[xy - xy.mean(axis=0) + 0.05, np.zeros(len(xy))]


def _lab_file(path: Path, arrays: dict, yaw_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Markers laid out like the twin's, each moving with its nearest mass, written as lab
    states in a frame where the phantom is turned about the vertical (the twin turns it up to
    8 degrees), tilted and shifted. Returns the layout (grid frame) and the masses it follows."""
    layout = _twin_layout()
    ij = np.rint(layout[:, [1, 0]] / MSMParams().spacing).astype(int)
    nearest = ij[:, 0] * 32 + ij[:, 1]
    rest = arrays["states/points"][0].astype(float)
    moved = layout + (arrays["states/points"][:, nearest] - rest[nearest])
    rot, shift = _rotation(yaw_deg, 4.0), np.array([0.31, -0.12, 0.85])
    pts = np.concatenate([moved, arrays["states/tip"][:, None]], axis=1) @ rot.T + shift
    lab = {**arrays, "states/points": pts.astype(np.float32),
           "states/valid": np.ones(pts.shape[:2], dtype=bool),
           "states/tip": (arrays["states/tip"] @ rot.T + shift).astype(np.float32),
           "states/force_vector": (arrays["states/force_vector"] @ rot.T).astype(np.float32)}
    attrs = file_attrs(_plan(), TRUE, 1e-6, {"stage": "test"}, None)
    attrs.update(source="lab")
    del attrs["msm_params"]
    write_states(path, lab, attrs)
    return layout, nearest


@pytest.mark.parametrize("yaw_deg", [7.5, -6.0, 0.0])
def test_lab_states_yawed_tilted_and_off_the_grid_land_on_the_grid(made, tmp_path, yaw_deg):
    _, a = made
    layout, nearest = _lab_file(tmp_path / "lab.h5", a, yaw_deg)
    sequences, params = read_measured(tmp_path / "lab.h5")
    assert params == MSMParams()                              # lab: the paper's grid
    first = sequences[0]
    np.testing.assert_allclose(first.rest[:-1], layout, atol=2e-6)   # float32 at ~1 m
    assert first.masses.tolist() == [*nearest, first.node]
    np.testing.assert_allclose(first.forces, a["states/force_vector"][1:5], atol=1e-5)


def test_lab_states_in_a_yawed_frame_give_the_constants(made, tmp_path):
    _lab_file(tmp_path / "lab.h5", made[1], 7.5)
    sequences, params = read_measured(tmp_path / "lab.h5")
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


def test_cli_refuses_a_start_where_the_msm_cannot_settle(made, tmp_path):
    """--start 1e6 1e-3 N/m (a stiffness ratio of 1e9) ends in seconds with one line, no file;
    the search from it used to run 300 failing trials and write Infinity."""
    out = tmp_path / "params.json"
    result = CliRunner().invoke(cli, ["fit-msm", str(made[0]), "--out", str(out),
                                      "--max-sequences", "1", "--start", "1e6", "1e-3"])
    assert result.exit_code == 2, result.output
    assert result.output.startswith("error: --start:") and len(result.output.splitlines()) == 1
    assert "cannot settle at --start 1e+06 0.001" in result.output
    assert not out.exists()


def test_a_fit_whose_every_trial_fails_is_refused(made, monkeypatch):
    def unsettled(*args, **kwargs):
        raise MSMError("static solve did not converge")

    sequences, params = read_measured(made[0])
    monkeypatch.setattr(msm_fit, "mean_distance", unsettled)
    with pytest.raises(BadInput, match="cannot settle"):
        fit_msm(sequences, params)

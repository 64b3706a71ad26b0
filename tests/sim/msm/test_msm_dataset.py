"""`pipeline simulate`: the paper's protocol as a states file, shards and merge, the recording."""

from __future__ import annotations

import json
import math
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from core.recording import rrd_entities, rrd_has_blueprint, rrd_timelines
from data_schema.hdf5 import validate_h5
from data_schema.states import STATES
from pipeline.cli import cli
from sim.msm.msm import MSM, MSMError, unit
from sim.msm.msm_dataset import write_states
from sim.msm.msm_protocol import Protocol, draw_plan
from sim.msm.msm_static import residual

SMALL = ["--locations", "3", "--directions", "2", "--steps", "4", "--seed", "7"]


def _run(*args: str) -> object:
    return CliRunner().invoke(cli, ["-q", "simulate", *args], catch_exceptions=False)


def _arrays(path: Path) -> dict[str, np.ndarray]:
    with h5py.File(path, "r") as f:
        names: list[str] = []
        f.visititems(lambda n, o: names.append(n) if isinstance(o, h5py.Dataset) else None)
        return {n: f[n][()] for n in names}


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("msm") / "msm.h5"
    result = _run("--out", str(out), *SMALL, "--workers", "1", "--rrd-sequences", "3")
    assert result.exit_code == 0, result.output
    return out


# -- the plan ----------------------------------------------------------------------------------

def test_plan_follows_the_protocol():
    plan = draw_plan(Protocol(), 1024)
    assert len(set(plan.nodes.tolist())) == 100
    assert plan.directions.shape == (100, 11, 3)
    assert np.allclose(np.linalg.norm(plan.directions, axis=-1), 1.0)
    assert np.allclose(plan.directions[:, 0], [0, 0, -1])
    angle = np.degrees(np.arccos(-plan.directions[:, 1:, 2]))
    assert angle.max() <= 45.0 and angle.min() > 0
    # uniform on the spherical cap: cos(angle) uniform on [cos 45, 1]
    assert np.mean(-plan.directions[:, 1:, 2]) == pytest.approx((1 + math.cos(math.pi / 4)) / 2,
                                                                abs=0.01)
    m = plan.multi
    assert m.shape == (1100, 15, 2)
    assert np.all(m[..., 1] - m[..., 0] >= 2) and m.min() >= 0 and m.max() <= 15
    assert all(len({tuple(p) for p in seq}) == 15 for seq in m)
    again = draw_plan(Protocol(), 1024)
    assert all(np.array_equal(a, b) for a, b in
               zip((plan.nodes, plan.directions, plan.multi),
                   (again.nodes, again.directions, again.multi), strict=True))


def test_few_steps_give_fewer_multi_pairs():
    plan = draw_plan(Protocol(locations=1, directions=1, steps=3), 1024)
    assert sorted(map(tuple, plan.multi[0].tolist())) == [(0, 2), (0, 3), (1, 3)]


# -- the file ----------------------------------------------------------------------------------

def test_layout_of_the_states_file(small):
    validate_h5(small, STATES)
    a = _arrays(small)
    L, D, T = 3, 2, 5
    assert a["states/points"].shape == (L * D * T, 1024, 3)
    assert a["states/points"].dtype == np.float32
    seq, step = a["states/sequence"], a["states/step"]
    assert np.array_equal(seq, np.repeat(np.arange(L * D), T))
    assert np.array_equal(step, np.tile(np.arange(T), L * D))
    assert np.array_equal(a["states/location"], seq // D)
    assert np.allclose(a["states/force"], step * 7.5 / 4)
    assert np.allclose(np.linalg.norm(a["states/force_vector"], axis=1), a["states/force"],
                       atol=1e-5)
    model = MSM()
    assert np.allclose(a["states/points"][step == 0], model.rest, atol=1e-7)
    plan = draw_plan(Protocol(locations=3, directions=2, steps=4, seed=7), 1024)
    nodes = np.repeat(plan.nodes, D * T)
    assert np.array_equal(a["states/tip"], a["states/points"][np.arange(len(seq)), nodes])
    s, e = a["single/start"], a["single/end"]
    assert len(s) == L * D * 4 and np.all(e == s + 1) and np.all(seq[s] == seq[e])
    s, e = a["multi/start"], a["multi/end"]
    assert len(s) == L * D * 6                       # all 6 pairs two or more steps apart
    assert np.all(seq[s] == seq[e]) and np.all(step[e] - step[s] >= 2)
    with h5py.File(small, "r") as f:
        assert f.attrs["source"] == "msm" and f.attrs["units_length"] == "m"
        assert json.loads(f.attrs["msm_params"])["k_fixed"] == 21.0
        assert json.loads(f.attrs["protocol"])["seed"] == 7
        assert json.loads(f.attrs["provenance"])["stage"] == "simulate"


def test_states_are_equilibria_and_the_file_says_how_exactly(small):
    """Every loaded state balances its load: to --tol as solved (float64), and to the float32
    floor as stored; the file's residual attributes are the worst over all of them."""
    a = _arrays(small)
    model = MSM()
    plan = draw_plan(Protocol(locations=3, directions=2, steps=4, seed=7), 1024)
    stored = []
    for k in np.flatnonzero(a["states/step"] > 0):
        loc, seq, t = a["states/location"][k], a["states/sequence"][k], a["states/step"][k]
        force = unit(plan.directions[loc, seq % 2]) * 7.5 * t / 4
        load = model.load(plan.nodes[loc], force)
        stored.append(residual(model, a["states/points"][k].astype(float), load))
    with h5py.File(small, "r") as f:
        solved_attr, stored_attr = f.attrs["max_residual_N"], f.attrs["stored_residual_N"]
    assert solved_attr < 1e-6                            # --tol (default)
    assert max(stored) == pytest.approx(stored_attr, rel=1e-12)
    # float32 rounds positions by up to ~4e-9 m at 0.1 m: ~1e-6 N of spring force, above --tol
    assert solved_attr < stored_attr < 2e-5


def test_cli_line_reports_both_residuals(tmp_path):
    out = tmp_path / "one.h5"
    result = _run("--out", str(out), "--locations", "1", "--directions", "1", "--steps", "2",
                  "--workers", "1", "--no-rrd")
    assert result.exit_code == 0, result.output
    with h5py.File(out, "r") as f:
        solved, stored = f.attrs["max_residual_N"], f.attrs["stored_residual_N"]
    assert f"max residual {solved:.2g} N solved, {stored:.2g} N as stored" in result.output


def test_same_seed_and_any_worker_count_give_the_same_bytes(small, tmp_path):
    out = tmp_path / "two.h5"
    assert _run("--out", str(out), *SMALL, "--workers", "2", "--no-rrd").exit_code == 0
    a, b = _arrays(small), _arrays(out)
    assert a.keys() == b.keys()
    assert all(a[k].tobytes() == b[k].tobytes() for k in a)
    other = tmp_path / "other.h5"
    assert _run("--out", str(other), *SMALL[:-1], "8", "--workers", "1",
                "--no-rrd").exit_code == 0
    assert _arrays(other)["states/points"].tobytes() != a["states/points"].tobytes()


def test_shards_merge_into_the_one_run_arrays(small, tmp_path):
    parts = []
    for i in range(2):
        part = tmp_path / f"part{i}.h5"
        assert _run("--out", str(part), *SMALL, "--shard", f"{i}/2", "--workers", "1",
                    "--no-rrd").exit_code == 0
        validate_h5(part, STATES)
        parts.append(str(part))
    merged = tmp_path / "merged.h5"
    result = _run("--merge", parts[1], parts[0], "--out", str(merged), "--no-rrd")
    assert result.exit_code == 0, result.output
    a, b = _arrays(small), _arrays(merged)
    assert a.keys() == b.keys()
    assert all(a[k].tobytes() == b[k].tobytes() for k in a)
    with h5py.File(merged, "r") as f, h5py.File(small, "r") as one:
        assert "shard" not in f.attrs
        for key in ("max_residual_N", "stored_residual_N"):     # the worst of the shards
            assert f.attrs[key] == one.attrs[key]
        assert json.loads(f.attrs["provenance"])["stage"] == "simulate --merge"


def test_merge_refuses_incomplete_or_mixed_shards(tmp_path):
    parts = []
    for i, seed in ((0, "7"), (1, "8")):
        part = tmp_path / f"part{i}.h5"
        args = [*SMALL[:-1], seed, "--shard", f"{i}/2", "--workers", "1", "--no-rrd"]
        assert _run("--out", str(part), *args).exit_code == 0
        parts.append(str(part))
    out = tmp_path / "merged.h5"
    for shards, message in (([parts[0]], "missing"), (parts, "different run"),
                            ([parts[0], parts[0]], "given twice")):
        result = CliRunner().invoke(cli, ["simulate", "--merge", *shards, "--out", str(out)])
        assert result.exit_code == 2 and message in result.output, result.output
        assert result.output.startswith("error:") and len(result.output.splitlines()) == 1
        assert not out.exists()


@pytest.mark.parametrize("args,message", [
    (["--fmax", "-1"], "--fmax"),
    (["--locations", "2000"], "exceeds"),
    (["--shard", "2/2"], "--shard"),
    (["--shard", "x"], "I/N"),
    (["--k-fixed", "0"], "--k-fixed"),
    (["--tol", "0"], "--tol"),
    (["--fmax", "nan"], "--fmax"),
    (["--k-between", "inf"], "--k-between"),
    (["--contact-radius", "nan"], "--contact-radius"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, args, message):
    out = tmp_path / "x.h5"
    result = CliRunner().invoke(cli, ["simulate", "--out", str(out), "--locations", "1",
                                      "--directions", "1", "--steps", "1", *args])
    assert result.exit_code == 2, result.output
    assert result.output.startswith("error:") and message in result.output
    assert not out.exists() and not out.with_suffix(".rrd").exists()


def test_no_nan_state_is_ever_written(tmp_path):
    out = tmp_path / "nan.h5"
    points = np.zeros((2, 4, 3), np.float32)
    points[1, 2, 0] = np.nan
    with pytest.raises(MSMError, match="non-finite"):
        write_states(out, {"states/points": points}, {})
    assert not out.exists()


def test_recording_shows_surface_load_and_force(small):
    rrd = small.with_suffix(".rrd")
    entities = rrd_entities(rrd)
    surfaces = [e for e in entities if e.endswith("/surface")]
    assert len(surfaces) == 3
    for s in surfaces:
        root = s.rsplit("/", 1)[0]
        assert "Mesh3D" in entities[s]
        assert "Points3D" in entities[f"{root}/loaded"]
        assert "Arrows3D" in entities[f"{root}/force"]
        name = root.rsplit("/", 1)[1]
        assert "Scalars" in entities[f"/plots/{name}"]
    assert "ViewCoordinates" in entities["/"]
    assert rrd_timelines(rrd) == {"force_step"}
    assert rrd_has_blueprint(rrd)


# -- the MSM at a lab's layout ------------------------------------------------------------------

LAYOUT = np.array([[x, y, 0.0] for y in (0.03, 0.05, 0.07) for x in (0.031, 0.05, 0.069)])


def test_layout_states_are_the_full_grid_seen_at_the_markers(tmp_path):
    """Sampled at a layout, every state is the full-grid equilibrium's bilinear blend at each
    marker's rest position, the tip (last) the loaded patch's centre; loads fall inside the
    markers' footprint; the contact patch shares the load."""
    from sim.msm.msm_sampling import contact_masses, sample_at
    from sim.msm.msm_static import simulate_sequence
    from sim.msm.simulate_stage import generate

    protocol = Protocol(locations=2, directions=2, steps=3, fmax=3.0, seed=4,
                        contact_radius=0.004)
    path = tmp_path / "layout.h5"
    _, lay = generate(path, protocol, MSM().params, layout=LAYOUT)
    model = MSM()
    assert lay["states/points"].shape == (2 * 2 * 4, len(LAYOUT) + 1, 3)
    loaded = model.rest[lay["states/mass"], :2]
    assert ((loaded >= 0.03 - 1e-9) & (loaded <= 0.07 + 1e-9)).all()
    rows = np.flatnonzero(lay["states/sequence"] == 1)               # location 0, direction 1
    node, force = int(lay["states/mass"][rows[0]]), lay["states/force_vector"][rows[-1]]
    contact = contact_masses(model, model.rest[node, :2], 0.004)
    assert len(contact) == 5                        # the mass and its four row/column neighbours
    full = simulate_sequence(model, contact, force, steps=3, fmax=3.0)
    sampling = sample_at(model, LAYOUT[:, :2])
    for t, row in enumerate(rows):
        expected = LAYOUT + sampling.displace(full[t] - model.rest)
        np.testing.assert_allclose(lay["states/points"][row, :-1], expected, atol=2e-8)
        np.testing.assert_allclose(lay["states/points"][row, -1], full[t][contact].mean(0),
                                   atol=2e-8)
    np.testing.assert_array_equal(lay["states/points"][:, -1], lay["states/tip"])
    with h5py.File(path) as f:
        np.testing.assert_allclose(json.loads(f.attrs["layout"]), LAYOUT)


def test_a_marker_between_masses_follows_the_bilinear_blend():
    from sim.msm.msm_sampling import contact_masses, sample_at

    model = MSM()
    h = model.params.spacing_x
    point = np.array([[2.25 * h, 5.5 * h]])                 # a quarter and a half between masses
    s = sample_at(model, point)
    assert sorted(s.masses[0].tolist()) == sorted([5 * 32 + 2, 5 * 32 + 3, 6 * 32 + 2,
                                                   6 * 32 + 3])
    np.testing.assert_allclose(s.weights[0].sum(), 1.0)
    disp = np.zeros((model.N, 3))
    disp[:, 2] = model.rest[:, 0] * 2 + model.rest[:, 1] * 3    # a linear field: exact
    np.testing.assert_allclose(s.displace(disp)[0, 2], 2 * point[0, 0] + 3 * point[0, 1])
    assert len(contact_masses(model, model.rest[16 * 32 + 16, :2], 0.0)) == 1
    assert len(contact_masses(model, model.rest[16 * 32 + 16, :2], 1.01 * h)) == 5
    missing = sample_at(model, np.array([[np.nan, np.nan]]))
    assert (missing.weights == 0).all()


def test_a_layout_that_is_not_lab_states_is_one_line_and_no_file(small, tmp_path):
    out = tmp_path / "layout.h5"
    res = CliRunner().invoke(cli, ["simulate", "--out", str(out), "--layout", str(small),
                                   "--locations", "1", "--directions", "1", "--no-rrd"])
    assert res.exit_code == 2 and len(res.output.splitlines()) == 1, res.output
    assert "--layout needs extracted lab states" in res.output and not out.exists()

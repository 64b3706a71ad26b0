"""pipeline extract against the phantom twin's truth: the levels each press reached, the points
of each state, the force at it, the phantom frame; and its refusals."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from calib.phantom_frame import apply_transform
from core.recording import rrd_entities
from data_schema.states import validate_states
from pipeline.cli import cli


def _cli(*args: str):
    return CliRunner().invoke(cli, ["-q", *map(str, args)])


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Path:
    """A small twin session (2 locations x 2 presses), ingested, synced and extracted."""
    d = tmp_path_factory.mktemp("extract")
    for args in (("synth", d / "s", "--seed", "3", "--locations", "2", "--repeats", "2"),
                 ("ingest", d / "s", "--out", d / "s.mcap", "--no-rrd"),
                 ("sync", d / "s.mcap", "--out", d / "synced.h5", "--no-rrd"),
                 ("extract", d / "synced.h5", "--out", d / "states.h5")):
        res = _cli(*args)
        assert res.exit_code == 0, res.output
    return d


def _truth_levels(truth: h5py.File, press: int) -> int:
    """The highest level the true contact force of a press reached (what extraction must find;
    truth's own states stop at the planned peak, which hand tremor can overshoot)."""
    force = truth["force/magnitude"][()][truth["mocap/press"][()] == press]
    return int(np.floor(force.max() / 0.5 + 1e-9))


def test_levels_points_and_force_against_truth(session) -> None:
    validate_states(session / "states.h5")
    with h5py.File(session / "states.h5") as s, h5py.File(session / "s" / "truth.h5") as t:
        seq, step = s["states/sequence"][()], s["states/step"][()]
        pts, valid, force = s["states/points"][()], s["states/valid"][()], s["states/force"][()]
        to_phantom = s["sessions/transform"][0]
        t_pts, t_step, t_press = t["states/points"][()], t["states/step"][()], \
            t["states/press"][()]
        for press in np.unique(t_press):
            assert sorted(step[seq == press]) == list(range(_truth_levels(t, press) + 1))
        dist = []
        for i in np.flatnonzero(np.isin(step, t_step)):
            j = np.flatnonzero((t_press == seq[i]) & (t_step == step[i]))
            if j.size:
                true = apply_transform(to_phantom, t_pts[j[0]])
                dist.append(np.linalg.norm(pts[i][valid[i]] - true[valid[i]], axis=1).mean())
        assert np.mean(dist) < 0.15e-3                      # below the markers' own 0.18 mm
        np.testing.assert_allclose(force, 0.5 * step, atol=0.02)


def test_the_phantom_frame_is_the_true_one(session) -> None:
    """The true rest markers land on z = 0, on a grid centred on the 100 x 100 mm footprint,
    with x along the phantom's true x axis."""
    with h5py.File(session / "states.h5") as s, h5py.File(session / "s" / "truth.h5") as t:
        to_phantom = s["sessions/transform"][0]
        rest = apply_transform(to_phantom, t["phantom/rest_points"][()])
        true_x = t["phantom/to_lab"][()][:3, 0]
    np.testing.assert_allclose(rest[:, 2], 0, atol=0.1e-3)
    np.testing.assert_allclose(rest[:, :2].mean(axis=0), [0.05, 0.05], atol=0.2e-3)
    assert to_phantom[0, :3] @ true_x > np.cos(np.radians(0.5))


def test_examples_follow_the_paper(session) -> None:
    with h5py.File(session / "states.h5") as f:
        seq, step = f["states/sequence"][()], f["states/step"][()]
        s1, e1 = f["single/start"][()], f["single/end"][()]
        s2, e2 = f["multi/start"][()], f["multi/end"][()]
    assert (step[e1] - step[s1] == 1).all() and (seq[e1] == seq[s1]).all()
    assert (step[e2] - step[s2] >= 2).all() and (seq[e2] == seq[s2]).all()
    assert max(np.bincount(seq[s2])) <= 15
    assert sorted(set(seq)) == list(range(4))             # presses in time order


def test_seed_decides_the_multi_step_pairs(session, tmp_path) -> None:
    for seed in ("0", "1"):
        assert _cli("extract", session / "synced.h5", "--out", tmp_path / f"{seed}.h5",
                    "--seed", seed, "--no-rrd").exit_code == 0
    with h5py.File(session / "states.h5") as a, h5py.File(tmp_path / "0.h5") as b, \
            h5py.File(tmp_path / "1.h5") as c:
        assert np.array_equal(a["multi/start"][()], b["multi/start"][()])
        assert not np.array_equal(a["multi/end"][()], c["multi/end"][()])


def test_max_speed_drops_and_counts(session, tmp_path) -> None:
    out = tmp_path / "slow.h5"
    res = _cli("extract", session / "synced.h5", "--out", out, "--max-speed", "0.002",
               "--no-rrd")
    assert res.exit_code == 0, res.output
    with h5py.File(out) as f, h5py.File(session / "states.h5") as full:
        dropped = json.loads(f.attrs["excluded"])["too_fast"]
        assert dropped > 0
        assert len(f["states/step"]) + dropped == len(full["states/step"])
        assert (f["states/speed"][()] <= 0.002).all()


def test_two_sessions_get_their_own_ids(session, tmp_path) -> None:
    out = tmp_path / "two.h5"
    assert _cli("extract", session / "synced.h5", session / "synced.h5", "--out", out,
                "--no-rrd").exit_code == 0
    with h5py.File(out) as f:
        loc, seq, ses = f["states/location"][()], f["states/sequence"][()], \
            f["states/session"][()]
        assert set(ses) == {0, 1} and len(json.loads(f.attrs["session_names"])) == 2
        assert set(loc[ses == 0]).isdisjoint(loc[ses == 1])
        assert set(seq[ses == 0]).isdisjoint(seq[ses == 1])
    shared = tmp_path / "shared.h5"
    assert _cli("extract", session / "synced.h5", session / "synced.h5", "--out", shared,
                "--shared-locations", "--no-rrd").exit_code == 0
    with h5py.File(shared) as f:
        ses, loc = f["states/session"][()], f["states/location"][()]
        assert set(loc[ses == 0]) == set(loc[ses == 1])


def test_recording_shows_levels_and_states(session) -> None:
    ents = set(rrd_entities(session / "states.rrd"))
    assert {"/force/measured", "/force/levels", "/phantom/state", "/phantom/tip",
            "/presses"} <= ents


@pytest.mark.parametrize("fault", ["not_synced", "truncated", "version"])
def test_bad_input_is_one_line_and_no_file(session, tmp_path, fault) -> None:
    bad = tmp_path / "bad.h5"
    if fault == "not_synced":
        shutil.copy(session / "states.h5", bad)
    elif fault == "truncated":
        data = (session / "synced.h5").read_bytes()
        bad.write_bytes(data[: len(data) // 3])
    else:
        shutil.copy(session / "synced.h5", bad)
        with h5py.File(bad, "r+") as f:
            f.attrs["schema_version"] = "0.9"
    out = tmp_path / "out.h5"
    res = _cli("extract", bad, "--out", out)
    assert res.exit_code == 2, res.output
    assert "bad.h5" in res.output and "Traceback" not in res.output
    assert len(res.output.strip().splitlines()) == 1
    assert not out.exists() and not (tmp_path / "out.rrd").exists()

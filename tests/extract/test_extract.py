"""pipeline extract against the phantom twin's truth: the levels each press reached, the points
of each state, the force at it, the phantom frame; and its refusals."""

from __future__ import annotations

import json
import shutil
from dataclasses import asdict
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner
from helpers.truth_checks import check_states_against_truth, truth_levels

from core.recording import rrd_entities
from core.text import to_json
from extract.extract_params import ExtractParams
from extract.phantom_frame import apply_transform
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


def test_levels_points_and_force_against_truth(session) -> None:
    excluded = check_states_against_truth(session / "states.h5", session / "s" / "truth.h5")
    assert set(excluded.values()) == {0}                    # nothing dropped here


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


def test_sequences_are_the_presses_in_time_order(session) -> None:
    """Sequence n is the n-th press in time (truth numbers presses by start frame): its rest
    tip is at that press's true location, and its top level is that press's, which tells it
    from the other press at the same place."""
    with h5py.File(session / "states.h5") as s, h5py.File(session / "s" / "truth.h5") as t:
        assert (np.diff(t["presses/start_frame"][()]) > 0).all()
        seq, step, tip = s["states/sequence"][()], s["states/step"][()], s["states/tip"][()]
        contact = apply_transform(s["sessions/transform"][0], t["locations/contact"][()])
        where = t["presses/location"][()]
        tops = [truth_levels(t, k) for k in range(len(where))]
    assert sorted(set(seq)) == list(range(len(where)))
    for k in range(len(where)):
        rest_tip = tip[(seq == k) & (step == 0)][0]
        assert np.argmin(np.linalg.norm(contact[:, :2] - rest_tip[:2], axis=1)) == where[k]
        assert step[seq == k].max() == tops[k]
        twins = [tops[j] for j in range(len(where)) if where[j] == where[k] and j != k]
        assert tops[k] not in twins          # else this session could not tell them apart


def test_examples_follow_the_paper(session) -> None:
    """Single-step: every pair of consecutive reached levels; multi-step: min(15, all pairs at
    least two levels apart) per press, counted from the levels the true force reached."""
    with h5py.File(session / "states.h5") as f, h5py.File(session / "s" / "truth.h5") as t:
        seq, step = f["states/sequence"][()], f["states/step"][()]
        s1, e1 = f["single/start"][()], f["single/end"][()]
        s2, e2 = f["multi/start"][()], f["multi/end"][()]
        tops = [truth_levels(t, k) for k in range(len(t["presses/fmax"]))]
    assert (step[e1] - step[s1] == 1).all() and (seq[e1] == seq[s1]).all()
    assert (step[e2] - step[s2] >= 2).all() and (seq[e2] == seq[s2]).all()
    for k, top in enumerate(tops):
        assert np.sum(seq[s1] == k) == top
        assert np.sum(seq[s2] == k) == min(15, top * (top - 1) // 2)
    pairs = list(zip(s2.tolist(), e2.tolist(), strict=True))
    assert len(set(pairs)) == len(pairs)                    # drawn without replacement


def test_seed_decides_the_multi_step_pairs(session, tmp_path) -> None:
    for seed in ("0", "1"):
        assert _cli("extract", session / "synced.h5", "--out", tmp_path / f"{seed}.h5",
                    "--seed", seed, "--no-rrd").exit_code == 0
    pairs = {}
    for name, path in (("default", session / "states.h5"), ("0", tmp_path / "0.h5"),
                       ("1", tmp_path / "1.h5")):
        with h5py.File(path) as f:
            pairs[name] = {n: np.stack([f[f"{n}/start"][()], f[f"{n}/end"][()]], 1)
                           for n in ("single", "multi")}
    for n in ("single", "multi"):                           # the default seed is 0
        assert np.array_equal(pairs["default"][n], pairs["0"][n])
    assert np.array_equal(pairs["0"]["single"], pairs["1"]["single"])   # single: no draw
    assert not np.array_equal(pairs["0"]["multi"], pairs["1"]["multi"])


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
    for path, shared_locations in ((out, False), (shared, True)):    # every setting recorded
        with h5py.File(path) as f:
            recorded = json.loads(f.attrs["provenance"])["params"]
        assert recorded == json.loads(to_json(asdict(ExtractParams(
            shared_locations=shared_locations))))


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

"""pipeline split: groups never cross roles, test sets cover or say why not, the manifest ties
itself to its data, and the ten-line reader in docs/stages.md loads a fold without our code."""

from __future__ import annotations

import hashlib
import json
import os
import re
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner
from helpers.cgnn_data import write_dent_states
from helpers.paths import ROOT

from core.errors import BadInput
from core.recording import rrd_entities
from pipeline.cli import cli
from split.split import make_folds
from split.split_params import SplitParams

READER_DOC = ROOT / "docs" / "stages.md"   # the split manual: its ten-line reader


def _split(states: Path, out: Path, *args: str):
    return CliRunner().invoke(cli, ["-q", "split", str(states), "--out", str(out), *args])


@pytest.fixture(scope="module")
def states(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("split") / "states.h5"
    write_dent_states(path, places=5, repeats=4, steps=4)       # 20 presses at 5 places
    return path


def _group_of_examples(states: Path, group_by: str) -> dict[str, np.ndarray]:
    with h5py.File(states) as f:
        g = f[f"states/{group_by}"][()]
        return {s: g[f[f"{s}/start"][()]] for s in ("single", "multi")}


@pytest.mark.parametrize("group_by", ["sequence", "location"])
def test_groups_never_cross_roles(states, tmp_path, group_by) -> None:
    out = tmp_path / "s.json"
    ratio = "12:3:5" if group_by == "sequence" else "3:1:1"
    res = _split(states, out, "--group", group_by, "--ratio", ratio)
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    eg = _group_of_examples(states, group_by)
    for fold in doc["folds"]:
        roles = {r: set(fold[r]["groups"]) for r in ("train", "val", "test")}
        assert not (roles["train"] & roles["val"] or roles["train"] & roles["test"]
                    or roles["val"] & roles["test"])
        for role, groups in roles.items():
            for s in ("single", "multi"):
                assert set(eg[s][fold[role][s]]) <= groups       # examples follow their group
        n_all = sum(len(fold[r][s]) for r in roles for s in ("single", "multi"))
        assert n_all == sum(len(v) for v in eg.values())         # every example has a role


def test_test_sets_cover_or_the_manifest_says_why() -> None:
    groups = np.arange(20)
    folds, note = make_folds(groups, SplitParams("sequence", (12, 3, 5), folds=4, seed=1))
    tests = [set(f["groups"]["test"]) for f in folds]
    assert set().union(*tests) == set(groups) and sum(map(len, tests)) == 20   # disjoint
    assert "disjoint and cover" in note
    folds, note = make_folds(groups, SplitParams("sequence", (12, 3, 5), folds=5, seed=1))
    assert set().union(*(f["groups"]["test"] for f in folds)) == set(groups)
    assert "overlap" in note
    folds, note = make_folds(groups, SplitParams("sequence", (12, 3, 5), folds=2, seed=1))
    assert "cover 10 of 20" in note


@pytest.mark.parametrize(("folds", "overlap"), [(4, False), (5, True)])
def test_manifest_test_sets_over_20_presses(states, tmp_path, folds, overlap) -> None:
    """20 presses at 12:3:5 give 5 test presses a fold: 4 folds test each press once, 5 folds
    (25 > 20) cover every press with some tested twice, and the manifest's note says so."""
    out = tmp_path / "s.json"
    assert _split(states, out, "--folds", str(folds)).exit_code == 0
    doc = json.loads(out.read_text())
    tests = [fold["test"]["groups"] for fold in doc["folds"]]
    assert len(tests) == folds and all(len(t) == 5 for t in tests)
    assert set().union(*map(set, tests)) == set(range(20))
    assert (sum(map(len, tests)) > 20) == overlap
    assert ("overlap" in doc["note"]) == overlap
    for fold in doc["folds"]:                         # nested subsets of 1..12 training presses
        subsets = fold["train_subsets"]
        assert [len(x) for x in subsets] == list(range(1, 13))
        assert all(set(a) < set(b) for a, b in zip(subsets, subsets[1:], strict=False))
        assert set(subsets[-1]) == set(fold["train"]["groups"])


def test_msm_defaults_hold_whole_locations_out(tmp_path) -> None:
    msm = tmp_path / "msm.h5"
    res = CliRunner().invoke(cli, ["-q", "simulate", "--out", str(msm), "--locations", "10",
                                   "--directions", "2", "--steps", "2", "--no-rrd"])
    assert res.exit_code == 0, res.output
    out = tmp_path / "s.json"
    assert _split(msm, out, "--no-rrd").exit_code == 0
    doc = json.loads(out.read_text())
    assert (doc["group_by"], doc["ratio"], doc["groups"]) == ("location", [7, 2, 1], 10)
    with h5py.File(msm) as f:
        loc = f["states/location"][()]
        where = {n: loc[f[f"{n}/start"][()]] for n in ("single", "multi")}
    for fold in doc["folds"]:
        assert [len(fold[r]["groups"]) for r in ("train", "val", "test")] == [7, 2, 1]
        for role in ("train", "val", "test"):             # both directions of a place go along
            held = {int(x) for n in where for x in where[n][fold[role][n]]}
            assert held == set(fold[role]["groups"])


def test_training_subsets_are_nested() -> None:
    folds, _ = make_folds(np.arange(20), SplitParams("sequence", (12, 3, 5), folds=5, seed=0))
    for f in folds:
        subsets = f["train_subsets"]
        assert [len(s) for s in subsets] == list(range(1, 13))
        assert all(set(a) < set(b) for a, b in zip(subsets, subsets[1:], strict=False))
        assert set(subsets[-1]) == set(f["groups"]["train"])


def test_a_ratio_that_does_not_fit_names_the_numbers() -> None:
    with pytest.raises(BadInput, match=r"12:3:5 does not fit 3 group\(s\).*train"):
        make_folds(np.arange(3), SplitParams("sequence", (12, 3, 5)))


def test_manifest_names_its_data_and_defaults_follow_it(states, tmp_path) -> None:
    out = tmp_path / "s.json"
    assert _split(states, out).exit_code == 0
    doc = json.loads(out.read_text())
    assert doc["data"]["sha256"] == hashlib.sha256(states.read_bytes()).hexdigest()
    assert (doc["group_by"], doc["ratio"]) == ("sequence", [12, 3, 5])      # lab defaults
    assert {"/footprint/train", "/footprint/val", "/footprint/test", "/folds"} <= \
        set(rrd_entities(tmp_path / "s.rrd"))


def test_cli_refuses_a_ratio_that_does_not_fit(tmp_path) -> None:
    small = tmp_path / "small.h5"
    write_dent_states(small, places=3, repeats=1, steps=3)
    out = tmp_path / "s.json"
    res = _split(small, out)
    assert res.exit_code == 2 and "does not fit 3 group(s)" in res.output
    assert not out.exists()


def _readme_reader() -> str:
    text = READER_DOC.read_text()
    section = text.split("Reading a fold without our code", 1)[1]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_the_readme_reader_loads_a_fold_without_our_code(states, tmp_path) -> None:
    out = tmp_path / "splits.json"
    assert _split(states, out).exit_code == 0
    os.symlink(states, tmp_path / states.name)
    code = _readme_reader()
    assert len(code.strip().splitlines()) <= 12 and "import train" not in code
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        env: dict = {}
        exec(code, env)                                   # noqa: S102 - the manual's own text
    finally:
        os.chdir(cwd)
    fold = json.loads(out.read_text())["folds"][0]["train"]
    n = len(fold["single"]) + len(fold["multi"])
    assert env["inputs"].shape[0] == env["targets"].shape[0] == env["cond"].shape[0] == n
    assert env["cond"].shape[1] == 6 and env["dforce"].shape == (n,)
    # the dent model's truth: the tip sinks 1 mm per 0.5 N, the surface stays on the grid
    np.testing.assert_allclose(env["cond"][:, 2] - env["cond"][:, 5],
                               env["dforce"] / 0.5 * 1e-3, atol=1e-6)
    np.testing.assert_allclose(env["inputs"][..., :2], env["targets"][..., :2], atol=1e-7)
    assert (env["targets"][..., 2] <= env["inputs"][..., 2] + 1e-9).all()


def test_presses_that_repeat_places_are_held_out_place_by_place() -> None:
    """5 places pressed 4 times (the quick demo's lab): every fold tests one press of each place
    and validates on presses at three different places; and every press is tested once."""
    places = {press: press % 5 for press in range(20)}
    for seed in range(4):
        folds, _ = make_folds(np.arange(20), SplitParams("sequence", (12, 3, 5), seed=seed),
                              places)
        for f in folds:
            assert sorted(places[p] for p in f["groups"]["test"]) == [0, 1, 2, 3, 4]
            val = [places[p] for p in f["groups"]["val"]]
            assert len(set(val)) == 3
        assert {p for f in folds for p in f["groups"]["test"]} == set(range(20))


def test_one_press_a_place_keeps_the_plain_shuffle() -> None:
    plan = SplitParams("sequence", (12, 3, 5), seed=3)
    plain, _ = make_folds(np.arange(20), plan)
    alone, _ = make_folds(np.arange(20), plan, {p: p for p in range(20)})
    assert plain == alone


def test_the_view_sets_presses_at_one_place_apart_so_each_role_shows() -> None:
    from split.split_view import FAN_MM, fanned

    places = {0: np.array([10.0, 20.0]), 1: np.array([10.2, 19.9]), 2: np.array([10.0, 20.0]),
              3: np.array([60.0, 60.0])}
    drawn = fanned(places)
    shared = np.array([drawn[g] for g in (0, 1, 2)])
    apart = np.linalg.norm(shared[:, None] - shared[None], axis=-1)[np.triu_indices(3, 1)]
    assert (apart > FAN_MM).all()                        # three dots, not one
    assert np.allclose(np.linalg.norm(shared - [10.07, 19.97], axis=1), FAN_MM, atol=0.3)
    np.testing.assert_array_equal(drawn[3], places[3])   # a place pressed once stays put

"""phantom.states 2.0: its validator checks meaning, not only shapes; 1.0 files are refused."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from click.testing import CliRunner
from helpers.cgnn_data import write_dent_states

from core.errors import BadInput
from data_schema.states import FLAT_REST_M, check_flat_rest, rest_off_flat, validate_states
from pipeline.cli import cli


@pytest.fixture
def dent(tmp_path):
    path = tmp_path / "states.h5"
    write_dent_states(path, places=2, repeats=1, steps=4)
    return path


def _edit(path, name, fn):
    with h5py.File(path, "r+") as f:
        data = f[name][()]
        fn(data)
        f[name][...] = data


@pytest.mark.parametrize(("name", "edit", "message"), [
    ("single/end", lambda a: a.__setitem__(0, 10_000), "outside"),
    ("multi/start", lambda a: a.__setitem__(0, -1), "outside"),
    ("single/end", lambda a: a.__setitem__(0, a[0] + 5), "joins two sequences"),
    ("single/end", lambda a: a.__setitem__(1, a[1] - 1), "does not move forward"),
    ("states/session", lambda a: a.__setitem__(0, 3), "session_names"),
])
def test_each_fault_of_meaning_is_named(dent, name, edit, message) -> None:
    validate_states(dent)
    _edit(dent, name, edit)
    with pytest.raises(BadInput, match=message):
        validate_states(dent)


def test_single_steps_are_exactly_one_level(dent) -> None:
    with h5py.File(dent, "r+") as f:
        step = f["states/step"][()]
        end = f["single/end"][()]
        end[0] = f["single/start"][0] + 2                 # two levels on, same sequence
        assert step[end[0]] - step[f["single/start"][0]] == 2
        f["single/end"][...] = end
    with pytest.raises(BadInput, match="not 1 level"):
        validate_states(dent)


def test_multi_steps_are_at_least_two_levels(dent) -> None:
    with h5py.File(dent, "r+") as f:
        step, seq = f["states/step"][()], f["states/sequence"][()]
        start, end = f["multi/start"][()], f["multi/end"][()]
        end[0] = start[0] + 1                             # the next state: one level on
        assert seq[end[0]] == seq[start[0]] and step[end[0]] - step[start[0]] == 1
        f["multi/end"][...] = end
    with pytest.raises(BadInput, match="less than 2 levels apart"):
        validate_states(dent)


def test_a_valid_point_must_be_finite(dent) -> None:
    _edit(dent, "states/points", lambda a: a.__setitem__((0, 0, 0), np.nan))
    with pytest.raises(BadInput, match="not finite"):
        validate_states(dent)
    _edit(dent, "states/valid", lambda a: a.__setitem__((0, 0), False))
    validate_states(dent)                                  # flagged invalid: allowed


def test_version_1_files_are_refused_with_the_way_out(dent) -> None:
    with h5py.File(dent, "r+") as f:
        f.attrs["schema_version"] = "1.0"
    with pytest.raises(BadInput, match="regenerate"):
        validate_states(dent)


def test_msm_states_are_in_the_phantom_frame(tmp_path) -> None:
    out = tmp_path / "msm.h5"
    res = CliRunner().invoke(cli, ["-q", "simulate", "--out", str(out), "--locations", "2",
                                   "--directions", "2", "--steps", "4", "--no-rrd"])
    assert res.exit_code == 0, res.output
    validate_states(out)
    with h5py.File(out) as f:
        pts, step, mass = f["states/points"][()], f["states/step"][()], f["states/mass"][()]
        seq, fvec = f["states/sequence"][()], f["states/force_vector"][()]
        assert f["states/valid"][()].all()
        assert len(set(seq)) == 4 and len(set(f["states/location"][()])) == 2
    rest = pts[step == 0]
    np.testing.assert_allclose(rest[..., 2], 0, atol=1e-9)                  # rest surface z = 0
    assert rest[..., :2].min() >= -1e-9 and rest[..., :2].max() <= 0.1 + 1e-9  # on [0, 0.1]^2
    spacing = np.diff(np.unique(rest[0, :, 0])).min()
    assert rest[..., :2].max() - rest[..., :2].min() > 0.1 - 1.5 * spacing  # spans the footprint
    loaded_mass_z = pts[np.arange(len(step)), mass, 2]
    normal = (step == 4) & (seq % 2 == 0)                  # direction 0 is the normal
    np.testing.assert_allclose(fvec[normal] / np.linalg.norm(fvec[normal], axis=1)[:, None],
                               [[0, 0, -1]] * normal.sum(), atol=1e-6)
    assert (loaded_mass_z[normal] < -1e-3).all()           # the normal load pushes into -z
    for s in set(seq):                                     # deeper at every level
        assert (np.diff(loaded_mass_z[seq == s][np.argsort(step[seq == s])]) < 0).all()


def test_one_presss_stray_marker_does_not_make_a_flat_phantom_curved() -> None:
    """Each marker's rest height is its median over the presses: a marker read 5.3 mm up in
    one press of 32 (a mislabelled frame) leaves the phantom flat; markers that every press
    finds 10 mm up are a curved phantom's, refused where a flat block is simulated."""
    rng = np.random.default_rng(0)
    rest = np.zeros((32, 25, 3))
    rest[..., 2] = rng.normal(0.0, 2e-5, (32, 25))
    rest[5, 20, 2] = 5.3e-3
    assert rest_off_flat(rest) < 1e-4
    check_flat_rest(rest, "flat.h5")
    rest[:, 12, 2] += 10e-3                       # the middle marker on a dome's top
    assert abs(rest_off_flat(rest) - 10e-3) < 1e-4 and rest_off_flat(rest[0]) > FLAT_REST_M
    with pytest.raises(BadInput, match="curved"):
        check_flat_rest(rest, "dome.h5")

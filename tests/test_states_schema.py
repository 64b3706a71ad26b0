"""phantom.states 2.0: its validator checks meaning, not only shapes; 1.0 files are refused."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from cgnn_data import write_dent_states
from click.testing import CliRunner

from core.errors import BadInput
from data_schema.states import validate_states
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
    ("single/end", lambda a: a.__setitem__(0, a[0] + 5), "joins two sequences"),
    ("single/end", lambda a: a.__setitem__(1, a[1] - 1), "does not move forward"),
    ("multi/end", lambda a: a.__setitem__(0, a[0] - 1), "less than 2 levels|forward"),
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
                                   "--directions", "1", "--steps", "3", "--no-rrd"])
    assert res.exit_code == 0, res.output
    validate_states(out)
    with h5py.File(out) as f:
        pts, step, mass = f["states/points"][()], f["states/step"][()], f["states/mass"][()]
        assert f["states/valid"][()].all()
        fvec = f["states/force_vector"][()]
    rest = pts[step == 0]
    np.testing.assert_allclose(rest[..., 2], 0, atol=1e-9)                  # rest surface z = 0
    assert rest[..., :2].min() >= -1e-9 and rest[..., :2].max() <= 0.1 + 1e-9  # on [0, 0.1]^2
    loaded = np.flatnonzero(step == 3)
    rows = np.arange(len(step))
    assert (pts[rows, mass][loaded, 2] < -1e-3).all()      # the normal load pushes into -z
    assert (fvec[loaded, 2] < 0).all()

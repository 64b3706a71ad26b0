"""Any phantom: session.toml's [phantom] layout, the frame it fixes against a known placement,
a curved phantom refused, and any number of markers through the synced contract."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

from calib.rest_plane import rest_plane
from core.errors import BadInput
from data_schema.phantom import PhantomLayout, read_layout
from data_schema.synced import validate_synced
from extract.phantom_frame import apply_transform, to_phantom_frame
from pipeline.cli import cli

NAMES = [f"M{k:02d}" for k in range(20)]


def placed(xy_mm: np.ndarray, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Footprint points (mm, z = 0) placed in a lab by a known rigid motion: (lab m, to_lab)."""
    rot = Rotation.from_euler("zyx", [30, 8, -5], degrees=True).as_matrix()
    shift = np.array([1.1, -0.4, 0.8])
    pts = np.c_[xy_mm / 1000.0, np.zeros(len(xy_mm))]
    return pts @ rot.T + shift, rot


@pytest.mark.parametrize("table, what", [
    ({"size": [1, 2]}, "unknown key"),
    ({"size_mm": [150, -80]}, "two positive lengths"),
    ({"x_axis": ["M00", "Q9"]}, "'Q9', not a phantom marker"),
    ({"x_axis": ["M00", "M00"]}, "two different markers"),
    ({"rows": 3}, "equal rows"),
    ({"anchor": "M01"}, "come together"),
    ({"anchor": "Q1", "anchor_mm": [1, 2]}, "not a phantom marker"),
    ({}, "form no square grid"),
])
def test_a_layout_no_frame_can_come_from_is_refused_in_one_line(table, what):
    with pytest.raises(BadInput, match=what) as e:
        read_layout(Path("s/session.toml"), table, NAMES)
    assert e.value.path == "s/session.toml" and "\n" not in e.value.line()


def test_fewer_than_four_markers_are_refused():
    with pytest.raises(BadInput, match="at least 4"):
        read_layout(Path("session.toml"), None, NAMES[:3])


def test_the_interior_keys_are_read_elsewhere_and_leave_the_frame_as_it_was():
    """``interior`` and ``[phantom.labels]`` belong to fit-solid (data_schema/interior.py):
    the frame's layout is the same with them as without."""
    plain = {"size_mm": [150, 80], "x_axis": ["M03", "M07"]}
    inside = {**plain, "interior": "interior.nii.gz", "labels": {"1": 3.0}}
    assert read_layout(Path("s.toml"), inside, NAMES) == read_layout(Path("s.toml"), plain, NAMES)


def test_layout_round_trips_through_json():
    layout = read_layout(Path("s.toml"), {"size_mm": [150, 80], "x_axis": ["M03", "M07"],
                                          "anchor": "M00", "anchor_mm": [12.5, 10]}, NAMES)
    assert layout.size_m == (0.15, 0.08) and layout.anchor_m == (0.0125, 0.01)
    assert PhantomLayout.from_json(layout.as_json()) == layout
    assert PhantomLayout.from_json(None) == PhantomLayout()          # files from before


def test_scattered_markers_with_an_axis_and_anchor_land_where_they_lie():
    """20 markers anywhere on a 150 x 80 mm block, tilted, yawed, 1.1 m out: the frame from
    x_axis + anchor puts every marker at its footprint coordinates (the truth), to 1e-12 m."""
    rng = np.random.default_rng(4)
    xy = np.c_[rng.uniform(10, 140, 20), rng.uniform(8, 72, 20)]
    xy[0], xy[1] = (15.0, xy[0, 1]), (135.0, xy[0, 1])   # M00 -> M01 runs along +x
    lab, rot = placed(xy)
    layout = PhantomLayout(size_m=(0.15, 0.08), x_axis=("M00", "M01"), anchor="M05",
                           anchor_m=tuple(xy[5] / 1000.0))
    t = to_phantom_frame(lab, NAMES, lab[0], rot[:, 2], layout)
    np.testing.assert_allclose(apply_transform(t, lab)[:, :2], xy / 1000.0, atol=1e-12)
    np.testing.assert_allclose(apply_transform(t, lab)[:, 2], 0.0, atol=1e-12)


def test_a_grid_of_rows_fixes_x_and_centres_on_the_footprint():
    """4 rows of 6 (24 markers: no square), listed row-major, rows along +x, centred."""
    xy = np.array([[20.0 + 22 * c, 25.0 + 10 * r] for r in range(4) for c in range(6)])
    xy += [150 / 2 - xy[:, 0].mean(), 80 / 2 - xy[:, 1].mean()]
    lab, rot = placed(xy)
    names = [f"G{k}" for k in range(24)]
    t = to_phantom_frame(lab, names, lab[3], rot[:, 2], PhantomLayout((0.15, 0.08), rows=4))
    np.testing.assert_allclose(apply_transform(t, lab)[:, :2], xy / 1000.0, atol=1e-12)


def test_curved_phantom_is_refused_and_a_flat_noisy_one_is_not():
    rng = np.random.default_rng(1)
    xy = np.c_[rng.uniform(-40, 40, 30), rng.uniform(-40, 40, 30)] / 1000.0
    up = np.tile([0.0, 0.0, 1.0], (50, 1))
    flat = np.c_[xy, rng.normal(0, 1e-4, 30)]            # 0.1 mm marker noise
    frames = np.repeat(flat[None], 50, axis=0)
    _, normal = rest_plane(frames, up, "trial.tsv")
    assert abs(normal @ [0, 0, 1]) > 0.999
    dome = np.c_[xy, np.sqrt(0.06 ** 2 - (xy ** 2).sum(axis=1))]    # a 60 mm radius cap
    with pytest.raises(BadInput, match=r"trial\.tsv: the phantom markers at rest lie .* curved"):
        rest_plane(np.repeat(dome[None], 50, axis=0), up, "trial.tsv")


def _synced_copy(src: Path, dst: Path, keep: int) -> None:
    """A copy of a synced file with only its first ``keep`` phantom markers (and the tip)."""
    with h5py.File(src) as f, h5py.File(dst, "w") as g:
        for k, v in f.attrs.items():
            g.attrs[k] = v
        for name in ("calibration", "locations"):
            f.copy(name, g)
        names = f["point_names"][()]
        g["point_names"] = np.r_[names[:keep], names[-1:]]
        for key, press in f["presses"].items():
            out = g.create_group(f"presses/{key}")
            for k, v in press.attrs.items():
                out.attrs[k] = v
            for name, ds in press.items():
                data = ds[()]
                if name in ("points", "quality"):
                    data = np.concatenate([data[:, :keep], data[:, -1:]], axis=1)
                out[name] = data
                for k, v in ds.attrs.items():
                    out[name].attrs[k] = v
        g["presses"].attrs.update(f["presses"].attrs)


@pytest.fixture(scope="module")
def synced(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("layout")
    runner = CliRunner()
    for args in (("synth", d / "s", "--locations", "2", "--repeats", "1", "--pivot-seconds", "4",
                  "--no-rrd"),
                 ("ingest", d / "s", "--out", d / "s.mcap", "--no-rrd"),
                 ("sync", d / "s.mcap", "--out", d / "s.h5", "--no-rrd")):
        res = runner.invoke(cli, ["-q", *map(str, args)])
        assert res.exit_code == 0, res.output
    return d / "s.h5"


def test_synced_contract_takes_any_marker_count(synced, tmp_path):
    """16 markers (a 4 x 4 grid's worth) pass; a press whose points disagree with the names,
    and fewer than 4 markers, are refused."""
    ok = tmp_path / "16.h5"
    _synced_copy(synced, ok, 16)
    validate_synced(ok)
    with h5py.File(ok, "a") as f:
        del f["point_names"]
        f["point_names"] = [f"M{k}" for k in range(20)] + ["tip"]
    with pytest.raises(BadInput, match="points holds 17 points, but point_names names 21"):
        validate_synced(ok)
    few = tmp_path / "3.h5"
    _synced_copy(synced, few, 3)
    with pytest.raises(BadInput, match="at least 4 markers"):
        validate_synced(few)


def test_extract_refuses_two_phantoms_in_one_states_file(synced, tmp_path):
    other = tmp_path / "16.h5"
    _synced_copy(synced, other, 16)
    with h5py.File(other, "a") as f:           # 16 of a 5 x 5 grid: +x from P00 to P04
        f.attrs["phantom"] = json.dumps(PhantomLayout(x_axis=("P00", "P04")).as_json())
    res = CliRunner().invoke(cli, ["-q", "extract", str(synced), str(other), "--out",
                                   str(tmp_path / "st.h5"), "--no-rrd"])
    assert res.exit_code == 2 and "one states file holds one phantom" in res.output
    assert not (tmp_path / "st.h5").exists()


def test_ingest_refuses_a_marker_the_mocap_lacks_before_reading_the_force_log(synced, tmp_path):
    """session.toml names a phantom marker the export lacks: refused in one line naming the
    mocap export, before the (here broken) force log is read."""
    import shutil
    import tomllib

    folder = tmp_path / "s"
    shutil.copytree(synced.parent / "s", folder)
    toml = (folder / "session.toml").read_text()
    names = tomllib.loads(toml)["mocap"]["phantom_markers"]
    toml = toml.replace(f'"{names[-1]}"]', '"P99"]', 1)
    (folder / "session.toml").write_text(toml)
    force = tomllib.loads(toml)["force"]["file"]
    (folder / force).write_bytes(b"\x00garbage")
    res = CliRunner().invoke(cli, ["-q", "ingest", str(folder), "--out", str(tmp_path / "o.mcap")])
    assert res.exit_code == 2, res.output
    mocap = tomllib.loads(toml)["mocap"]["file"]
    assert res.output.strip() == f"error: {folder / mocap}: marker(s) named in session.toml " \
                                 "not in file: P99"
    assert not (tmp_path / "o.mcap").exists()


@pytest.mark.parametrize("xy_mm, rows", [
    (np.array([[10.0 + 20 * c, 20.0 + 20 * r] for r in range(4) for c in range(9)]), None),
    (np.random.default_rng(2).uniform(10, 90, (25, 2)), None),                  # scattered
    (np.array([[10.0 + 20 * c, 20.0 + 10 * r] for r in range(9) for c in range(4)]), 6),
])
def test_markers_that_are_not_the_grid_the_layout_says_are_refused(xy_mm, rows):
    """36 markers in 4 rows of 9 (no `rows`: read as 6 x 6), 25 scattered (no `x_axis`), 9
    rows of 4 said to be 6 rows: a count alone would turn the frame silently."""
    lab, rot = placed(xy_mm)
    names = [f"M{k}" for k in range(len(xy_mm))]
    with pytest.raises(BadInput, match=r"not a line|degrees apart"):
        to_phantom_frame(lab, names, lab[0], rot[:, 2], PhantomLayout((0.2, 0.1), rows=rows))


def test_a_hand_placed_grid_within_a_millimetre_is_a_grid():
    rng = np.random.default_rng(5)
    xy = np.array([[20.0 + 15 * c, 20.0 + 15 * r] for r in range(5) for c in range(5)])
    lab, rot = placed(xy + rng.uniform(-0.8, 0.8, xy.shape))
    t = to_phantom_frame(lab, NAMES[:25] if len(NAMES) >= 25 else [f"G{k}" for k in range(25)],
                         lab[0], rot[:, 2], PhantomLayout())
    assert np.degrees(np.arccos(t[0, :3] @ rot[:, 0])) < 1.5       # x within 1.5 degrees

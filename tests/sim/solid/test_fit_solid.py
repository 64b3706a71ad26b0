"""`pipeline fit-solid` and `simulate --solid`: a solid with a known lump inside, its presses
made by the solid itself, fitted back; then its pre-training set simulated at the markers.

Known truth: the material the states were made with (modulus, stiffening, contact radius,
the lump's 2.5x), on a coarse mesh (10 mm, 4 layers) so that each solve is milliseconds; the
fit must find them again from the states alone (a lab's file: force magnitudes, no vectors),
and refuse what the issue names in one line.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from core.recording import rrd_entities
from data_schema.hdf5 import write_h5
from data_schema.interior import read_interior, write_interior
from data_schema.states import STATES, validate_states
from extract.static_states import example_pairs
from pipeline.cli import cli
from sim.solid.block_mesh import BlockGeometry
from sim.solid.label_shares import label_shares
from sim.solid.solid_dataset import simulate_places
from sim.solid.solid_fit import SolidMaterial
from sim.solid.solid_model import Attachments, SolidModel

TOP, SPACING, LAYERS = -0.0015, 0.010, 4
TRUE = SolidMaterial(modulus=1.5e4, stiffening=2000.0, poisson=0.3, ratios=(1.0, 2.5),
                     contact_radius=0.015, reach=0.03)
MESH = ["--spacing-mm", "10", "--layers", "4"]


def _interior(folder: Path, ratio: str) -> None:
    """A 12 mm ball of label 1 centred 10 mm under (50, 50) mm, 1 mm voxels."""
    n = (100, 100, 36)
    affine = np.eye(4)
    affine[:3, 3] = [0.5, 0.5, -35.0]
    mm = np.stack(np.meshgrid(*[np.arange(k) for k in n], indexing="ij"), -1) + affine[:3, 3]
    ball = np.linalg.norm(mm - [50.0, 50.0, TOP * 1e3 - 10.0], axis=-1) <= 12.0
    folder.mkdir(parents=True, exist_ok=True)
    write_interior(folder / "interior.nii.gz", ball.astype(np.uint8), affine)
    (folder / "session.toml").write_text(
        f'[phantom]\ninterior = "interior.nii.gz"\n[phantom.labels]\n1 = {ratio}\n')


def _lab_states(path: Path, session: Path) -> None:
    """Presses at 9 places (3 x 3, 20 mm apart about the lump), one straight and one tilted,
    0 .. 4 N, as a lab's states file: 25 markers 1.5 mm above the silicone, then the tip."""
    g = 0.010 + 0.020 * np.arange(5)
    markers = np.array([[x, y, 0.0] for y in g for x in g])
    at = Attachments.riding(markers, TOP)
    model = SolidModel(BlockGeometry((0.1, 0.1), 0.032, TOP), SPACING, LAYERS)
    shares = label_shares(model.elasticity, read_interior(session / "interior.nii.gz"), 2)
    solver = model.factorise(shares @ np.array(TRUE.ratios), TRUE.poisson)
    places = np.array([[x, y, TOP] for y in (0.03, 0.05, 0.07) for x in (0.03, 0.05, 0.07)])
    tilt = np.array([np.sin(0.3), 0.0, -np.cos(0.3)])
    dirs = np.repeat(np.array([[[0.0, 0.0, -1.0], tilt]]), len(places), axis=0)
    forces = np.arange(9) * 0.5
    made = simulate_places(model, solver, TRUE, places, dirs, forces, at)
    n_seq, steps = 2 * len(places), len(forces)
    step, seq = np.tile(np.arange(steps), n_seq), np.repeat(np.arange(n_seq), steps)
    single, multi = example_pairs(step, seq, np.random.default_rng(0))
    arrays = {"states/points": made.points, "states/valid": np.ones(made.points.shape[:2], bool),
              "states/tip": made.tips, "states/force": np.tile(forces, n_seq).astype(np.float32),
              "states/step": step, "states/sequence": seq, "states/location": seq // 2,
              "states/session": np.zeros(len(step), int),
              "single/start": single[:, 0], "single/end": single[:, 1],
              "multi/start": multi[:, 0], "multi/end": multi[:, 1]}
    names = [f"P{k:02d}" for k in range(25)] + ["tip"]
    write_h5(path, STATES, arrays, {
        "provenance": "{}", "source": "lab", "units_length": "m", "units_force": "N",
        "step_n": 0.5, "frame": "phantom", "session_names": json.dumps(["solid"]),
        "point_names": json.dumps(names), "footprint_m": np.array([0.1, 0.1])})


@pytest.fixture(scope="module")
def lab(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("solid")
    _interior(root / "given", "2.5")
    _interior(root / "fit", '"fit"')
    _lab_states(root / "states.h5", root / "given")
    return root


def run(*args: object):
    return CliRunner().invoke(cli, ["-q", *map(str, args)])


@pytest.fixture(scope="module")
def fitted(lab: Path) -> dict:
    res = run("fit-solid", lab / "states.h5", "--session", lab / "fit", "--out",
              lab / "solid.json", *MESH)
    assert res.exit_code == 0, res.output + res.stderr
    return json.loads((lab / "solid.json").read_text())


def test_the_fit_finds_the_material_and_the_lumps_ratio_again(fitted: dict) -> None:
    m, sd = fitted["material"], fitted["sd"]
    assert m["modulus_pa"] == pytest.approx(TRUE.modulus, rel=0.01)
    assert m["stiffening_per_m2"] == pytest.approx(TRUE.stiffening, rel=0.05)
    assert m["contact_radius_m"] == pytest.approx(TRUE.contact_radius, rel=0.02)
    assert m["ratios"][1] == pytest.approx(2.5, rel=0.03)
    assert fitted["labels"]["fitted"] == [1] and np.isfinite(sd["ratio_1"])
    d = fitted["distances_mm"]
    assert d["solid"] < 0.01 < d["still"]                      # float32 storage only


def test_the_recording_shows_the_interior_the_solid_and_the_residuals(lab: Path,
                                                                     fitted: dict) -> None:
    found = rrd_entities(lab / "solid.rrd")
    assert "Boxes3D" in found["/interior/label_1"]
    meshes = [e for e, kinds in found.items() if e.endswith("/solid") and "Mesh3D" in kinds]
    assert meshes and all(e.startswith("/fit/seq_") for e in meshes)
    assert "BarChart" in found["/residual/per_marker"]


def test_simulate_solid_presses_the_fitted_solid_at_the_markers(lab: Path, fitted: dict
                                                                ) -> None:
    out = lab / "pre.h5"
    res = run("simulate", "--solid", lab / "solid.json", "--layout", lab / "states.h5",
              "--locations", 10, "--directions", 2, "--out", out, "--no-rrd")
    assert res.exit_code == 0, res.output + res.stderr
    validate_states(out)
    with h5py.File(out) as f, h5py.File(lab / "states.h5") as lab_file:
        assert f.attrs["source"] == "solid"
        assert json.loads(f.attrs["point_names"]) == json.loads(lab_file.attrs["point_names"])
        pts, step, force = f["states/points"][()], f["states/step"][()], f["states/force"][()]
        fvec = f["states/force_vector"][()]
    assert pts.shape == (10 * 2 * 16, 26, 3)
    rest = pts[step == 0]
    assert np.ptp(rest[:, :25], axis=0).max() < 1e-7          # every press starts at the layout
    np.testing.assert_allclose(np.linalg.norm(fvec, axis=1), force, atol=1e-5)
    sunk = rest[:, -1, 2] - pts[step == 15][:, -1, 2]
    assert np.all(sunk > 0.002)                               # each press dents the block
    split = run("split", out, "--out", lab / "pre_splits.json", "--no-rrd")
    assert split.exit_code == 0, split.output + split.stderr


@pytest.mark.parametrize(("labels", "match"), [
    ("1 = 25.0", "must be in"),
    ("2 = 3.0", "has only labels"),
    ("", "label 1 of the interior has no ratio"),
])
def test_bad_labels_are_refused_in_one_line_with_nothing_written(lab: Path, tmp_path: Path,
                                                                  labels: str, match: str
                                                                  ) -> None:
    session = tmp_path / "s"
    session.mkdir()
    (session / "interior.nii.gz").write_bytes((lab / "given" / "interior.nii.gz").read_bytes())
    (session / "session.toml").write_text(
        f'[phantom]\ninterior = "interior.nii.gz"\n[phantom.labels]\n{labels}\n')
    res = run("fit-solid", lab / "states.h5", "--session", session, "--out",
              tmp_path / "x.json", *MESH)
    assert res.exit_code == 2 and match in res.stderr and res.stderr.count("\n") == 1
    assert list(tmp_path.glob("x*")) == []


def test_a_volume_short_of_the_block_is_refused(lab: Path, tmp_path: Path) -> None:
    session = tmp_path / "s"
    session.mkdir()
    labels = read_interior(lab / "given" / "interior.nii.gz").labels[:, :, 20:]
    affine = np.eye(4)
    affine[:3, 3] = [0.5, 0.5, -15.0]
    write_interior(session / "interior.nii.gz", labels, affine)
    (session / "session.toml").write_text('[phantom]\ninterior = "interior.nii.gz"\n'
                                          '[phantom.labels]\n1 = 2.0\n')
    res = run("fit-solid", lab / "states.h5", "--session", session, "--out",
              tmp_path / "x.json", *MESH)
    assert res.exit_code == 2 and "does not cover the block" in res.stderr
    assert list(tmp_path.glob("x*")) == []


def test_solid_shards_merge_into_the_whole_run(lab: Path, fitted: dict, tmp_path: Path
                                               ) -> None:
    common = ["--solid", lab / "solid.json", "--layout", lab / "states.h5", "--locations", 4,
              "--directions", 2, "--no-rrd"]
    assert run("simulate", *common, "--out", tmp_path / "all.h5").exit_code == 0
    for i in range(2):
        res = run("simulate", *common, "--shard", f"{i}/2", "--out", tmp_path / f"p{i}.h5")
        assert res.exit_code == 0, res.output + res.stderr
    res = run("simulate", "--merge", tmp_path / "p0.h5", tmp_path / "p1.h5", "--out",
              tmp_path / "merged.h5", "--no-rrd")
    assert res.exit_code == 0, res.output + res.stderr
    with h5py.File(tmp_path / "all.h5") as a, h5py.File(tmp_path / "merged.h5") as m:
        assert m.attrs["source"] == "solid"
        for name in ("states/points", "states/sequence", "multi/start", "multi/end"):
            np.testing.assert_array_equal(a[name][()], m[name][()])


def test_simulate_solid_needs_a_layout(lab: Path, fitted: dict, tmp_path: Path) -> None:
    res = run("simulate", "--solid", lab / "solid.json", "--out", tmp_path / "x.h5")
    assert res.exit_code == 2 and "--layout" in res.stderr and res.stderr.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


def test_more_places_than_the_solid_has_are_refused_in_its_words(lab: Path, fitted: dict,
                                                                  tmp_path: Path) -> None:
    res = run("simulate", "--solid", lab / "solid.json", "--layout", lab / "states.h5",
              "--locations", 500, "--out", tmp_path / "x.h5")
    assert res.exit_code == 2 and "nodes inside the markers' bounding box" in res.stderr
    assert list(tmp_path.iterdir()) == []


def test_a_marker_never_seen_at_rest_or_a_file_without_a_tip_is_refused(lab: Path,
                                                                         tmp_path: Path) -> None:
    blind = tmp_path / "blind.h5"
    blind.write_bytes((lab / "states.h5").read_bytes())
    with h5py.File(blind, "r+") as f:
        pts, valid = f["states/points"][()], f["states/valid"][()]
        pts[:, 3] = np.nan
        valid[:, 3] = False
        f["states/points"][...], f["states/valid"][...] = pts, valid
    res = run("fit-solid", blind, "--out", tmp_path / "x.json", *MESH)
    assert res.exit_code == 2 and "point 3 is missing from every rest" in res.stderr
    msm = tmp_path / "msm.h5"
    assert run("simulate", "--locations", 2, "--directions", 1, "--out", msm,
               "--no-rrd").exit_code == 0
    res = run("fit-solid", msm, "--out", tmp_path / "y.json", *MESH)
    assert res.exit_code == 2 and "no tip as its last point" in res.stderr
    assert not list(tmp_path.glob("[xy]*"))

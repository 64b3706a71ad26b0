"""`pipeline synth` with a lump, a layer and a grid of places: truth.h5 records them, the
recording shows them, the presses feel them, and bad ones are refused in one line.

Two tiny sessions of the same seed (2 x 2 places, one press each), one with a 3x lump under
place 0 and a stiffer skin, one uniform: the hand, the places and the forces are the same
draws, so the presses differ only by the block.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from core.recording import rrd_entities
from data_schema.hdf5 import validate_h5
from data_schema.interior import session_interior
from data_schema.truth import REGIONS, TRUTH, read_regions
from pipeline.cli import cli

TINY = ["--locations", "2x2", "--repeats", "1", "--press-seconds", "3", "--pivot-seconds", "5",
        "--seed", "4"]
LUMP = "20,20,10,12,3"              # under place 0 (the 2x2 grid's corner at 20, 20 mm)
SKIN = "3,2"


def run(args: list[str]):
    return CliRunner().invoke(cli, ["-q", *args])


@pytest.fixture(scope="module")
def sessions(tmp_path_factory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("regions")
    lump, plain = root / "lump", root / "plain"
    res = run(["synth", str(lump), *TINY, "--inclusion", LUMP, "--layer", SKIN])
    assert res.exit_code == 0, res.output
    res = run(["synth", str(plain), *TINY, "--no-rrd"])
    assert res.exit_code == 0, res.output
    return lump, plain


def depth_at(folder: Path, force: float) -> np.ndarray:
    """(P,) how far each press's tip has sunk below its untouched contact at ``force`` N."""
    with h5py.File(folder / "truth.h5") as t:
        tip, f, press = t["states/points"][:, -1], t["states/force"][()], t["states/press"][()]
    return np.array([tip[(press == k) & (f == 0.0), 2][0] - tip[(press == k) & (f == force), 2][0]
                     for k in np.unique(press)])


def test_the_lump_makes_the_press_above_it_sink_less(sessions) -> None:
    """At 2 N the press over the lump sinks far less than the same press on the uniform block;
    the press at the opposite corner (85 mm from the lump) sinks about as much as there (the
    stiffer skin only)."""
    lump, plain = sessions
    with_lump, uniform = depth_at(lump, 2.0), depth_at(plain, 2.0)
    assert with_lump[0] < 0.8 * uniform[0]
    assert with_lump[3] == pytest.approx(uniform[3], rel=0.12)
    assert with_lump[3] < uniform[3]                           # the 2x skin


def test_truth_records_the_lump_and_the_layer_as_asked(sessions) -> None:
    lump, plain = sessions
    got = read_regions(lump / "truth.h5")
    np.testing.assert_allclose(got["inclusions/footprint"], [[0.020, 0.020]])
    np.testing.assert_allclose(got["inclusions/depth"], [0.010])
    np.testing.assert_allclose(got["inclusions/radius"], [0.012])
    np.testing.assert_allclose(got["inclusions/ratio"], [3.0])
    np.testing.assert_allclose(got["layers/thickness"], [0.003])
    np.testing.assert_allclose(got["layers/ratio"], [2.0])
    with h5py.File(lump / "truth.h5") as t:
        assert t.attrs["schema_version"] == TRUTH.version == "1.2"
        to_lab, contact = t["phantom/to_lab"][()], t["locations/contact"][0]
        np.testing.assert_allclose(t["phantom/size"][()], [0.1, 0.1, 0.032])
    # the centre: 10 mm straight below place 0's untouched contact, in the lab
    np.testing.assert_allclose(got["inclusions/centre"][0], contact - 0.010 * to_lab[:3, 2],
                               atol=1e-12)
    none = read_regions(plain / "truth.h5")
    assert all(none[p].shape[0] == 0 for p in REGIONS)


def test_a_1_1_truth_reads_as_a_uniform_block(sessions, tmp_path: Path) -> None:
    """A file from before 1.2 (1.2 less its new datasets) is valid and has no regions."""
    old = tmp_path / "truth.h5"
    old.write_bytes((sessions[0] / "truth.h5").read_bytes())
    with h5py.File(old, "r+") as f:
        for path in (*REGIONS, "phantom/size"):
            del f[path]
        f.attrs["schema_version"] = "1.1"
    validate_h5(old, TRUTH)
    got = read_regions(old)
    assert got["inclusions/centre"].shape == (0, 3) and got["layers/ratio"].shape == (0,)


def static_values(rrd: Path, entity: str, component: str) -> np.ndarray:
    """The static instances of ``component`` logged at ``entity``."""
    from rerun.chunk import RrdReader

    for chunk in RrdReader(str(rrd)).store().stream():
        if chunk.entity_path == entity and chunk.is_static:
            col = chunk.to_record_batch().column(component)
            return np.array(col[0].as_py())
    raise AssertionError(f"{entity} has no static {component}")


def test_the_recording_shows_the_lump_the_layer_and_the_places(sessions) -> None:
    lump, _ = sessions
    rrd = lump / "recording.rrd"
    found = rrd_entities(rrd)
    assert "Ellipsoids3D" in found["/phantom/inclusions"]
    assert "LineStrips3D" in found["/phantom/inclusion_outlines"]
    assert "Boxes3D" in found["/phantom/layer"]
    assert "Points3D" in found["/phantom/places"]
    with h5py.File(lump / "truth.h5") as t:
        centre, contacts = t["inclusions/centre"][()], t["locations/contact"][()]
        to_lab = t["phantom/to_lab"][()]
    np.testing.assert_allclose(static_values(rrd, "/phantom/inclusions", "Ellipsoids3D:centers"),
                               centre, atol=1e-6)
    np.testing.assert_allclose(static_values(rrd, "/phantom/inclusions",
                                             "Ellipsoids3D:half_sizes"), [[0.012] * 3], atol=1e-7)
    np.testing.assert_allclose(static_values(rrd, "/phantom/places", "Points3D:positions"),
                               contacts, atol=1e-6)
    box = static_values(rrd, "/phantom/layer", "Boxes3D:centers")[0]    # 1.5 mm down
    np.testing.assert_allclose(box, to_lab[:3, 3] + (0.032 - 0.0015) * to_lab[:3, 2], atol=1e-6)


@pytest.mark.parametrize("args, option", [
    (["--inclusion", "120,50,10,12,3"], "--inclusion"),
    (["--inclusion", "50,50,40,12,3"], "--inclusion"),
    (["--inclusion", "50,50,10,12,-2"], "--inclusion"),
    (["--inclusion", "50,50,10,12,20"], "--inclusion"),
    (["--inclusion", "50,50,10"], "--inclusion"),
    (["--inclusion", "50,50,10,12,3", "--inclusion", "55,50,10,12,3"], "--inclusion"),
    (["--size", "60x60", "--inclusion", "80,30,10,12,3"], "--inclusion"),
    (["--layer", "40,2"], "--layer"),
    (["--layer", "3,-1"], "--layer"),
    (["--layer", "3"], "--layer"),
    (["--locations", "6x5"], "--locations"),
    (["--locations", "0x3"], "--locations"),
    (["--locations", "11"], "--locations"),
    (["--locations", "5x5"], "--locations"),      # the default markers leave room for 4x4
])
def test_bad_regions_and_places_are_refused_in_one_line(tmp_path: Path, args, option) -> None:
    out = tmp_path / "s"
    res = CliRunner().invoke(cli, ["-q", "synth", str(out), "--repeats", "1", *args])
    assert res.exit_code == 2, (res.output, res.exception)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {option}"), res.stderr
    assert not out.exists() or not any(out.iterdir())


def test_the_interior_volume_shows_the_lump_and_the_layer_where_truth_has_them(sessions
                                                                                ) -> None:
    """synth writes interior.nii.gz (1 mm voxels, the states' phantom frame: the silicone's
    top 1.5 mm below the markers' centres) and names it in session.toml with the true ratios;
    the uniform session writes none."""
    lump, plain = sessions
    spec = session_interior(lump)
    assert spec is not None and spec.path.name == "interior.nii.gz"
    assert spec.ratios == {0: 1.0, 1: 2.0, 2: 3.0}             # the skin, then the lump
    top = -0.0015
    at = np.array([[0.020, 0.020, top - 0.010],                 # the lump's centre
                   [0.020, 0.020, top - 0.0235],                # just below it
                   [0.080, 0.080, top - 0.001],                 # in the skin, far from it
                   [0.080, 0.080, top - 0.005],                 # under the skin
                   [0.080, 0.080, top + 0.001]])                # above the silicone
    assert spec.interior.label_at(at).tolist() == [2, 0, 1, 0, 0]
    ball, cap = 4 / 3 * np.pi * 12.0**3, np.pi * 2.0**2 * (3 * 12.0 - 2.0) / 3
    voxels = int((spec.interior.labels == 2).sum())            # 1 mm^3 each
    assert voxels == pytest.approx(ball - cap, rel=0.03)       # the ball cut by the surface
    assert session_interior(plain) is None
    assert not (plain / "interior.nii.gz").exists()

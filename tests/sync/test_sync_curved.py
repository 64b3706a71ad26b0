"""A curved phantom through sync and extract, against the twin's truth: a dome twin (a cap
30 mm high on the default block) registered to its mould's STL, the tip's depth along the
surface normal where each press touched, the states in the shape's frame; and a marker moved
off the mould refused by name (exit 2, one line, nothing written)."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner
from helpers.truth_checks import check_states_against_truth

from core.recording import rrd_entities
from data_schema.synced import validate_synced
from extract.extract_stage import run_extract
from ingest.ingest_stage import run_ingest
from pipeline.cli import cli
from sim.twin.synth_params import SynthParams
from sim.twin.synth_stage import run_synth
from sync.sync_accuracy import TARGETS, curved_errors, sync_errors
from sync.sync_stage import run_sync


@pytest.fixture(scope="module")
def dome(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("dome")
    run_synth(None, d / "s", SynthParams(seed=3, locations=4, repeats=2, shape="dome:30"))
    run_ingest(d / "s", d / "s.mcap")
    run_sync(d / "s.mcap", d / "s.h5", rrd=d / "s.rrd")
    run_extract([d / "s.h5"], d / "states.h5")
    return d


def test_registration_depth_and_tip_against_truth(dome: Path) -> None:
    validate_synced(dome / "s.h5")
    curved = curved_errors(dome / "s.h5", dome / "s" / "truth.h5")
    assert curved["residual_max_mm"] < 0.3          # each marker on the registered mould
    assert curved["frame_mm"] < 0.1                 # the shape's frame where the truth has it
    assert curved["depth_rms_mm"] < 0.2             # along the normal where the tip touched
    errors = sync_errors(dome / "s.h5", dome / "s" / "truth.h5")
    assert errors["tip_rms_mm"] < TARGETS["tip_rms_mm"]
    assert errors["presses_missed"] == errors["presses_extra"] == 0


def test_each_press_measures_depth_from_where_it_touched(dome: Path) -> None:
    """The touch point lies on the true rest surface, near the true contact, and its normal
    is the true one there."""
    with h5py.File(dome / "s.h5") as s, h5py.File(dome / "s" / "truth.h5") as t:
        contact, normal = t["locations/contact"][()], t["presses/normal"][()]
        where = t["presses/location"][()]
        for k, key in enumerate(sorted(s["presses"])):
            g = s["presses"][key]
            assert np.linalg.norm(g["touch"][()] - contact[where[k]]) < 0.5e-3
            assert np.degrees(np.arccos(min(1.0, g["touch_normal"][()] @ normal[k]))) < 0.5


def test_states_in_the_shape_frame_against_truth(dome: Path) -> None:
    check_states_against_truth(dome / "states.h5", dome / "s" / "truth.h5")
    with h5py.File(dome / "states.h5") as s, h5py.File(dome / "s" / "truth.h5") as t:
        to_shape = s["sessions/transform"][0]
        true = np.linalg.inv(t["phantom/shape_to_lab"][()])
        np.testing.assert_allclose(to_shape[:3, :3], true[:3, :3], atol=1e-3)
        np.testing.assert_allclose(to_shape[:3, 3], true[:3, 3], atol=0.1e-3)


def test_recording_shows_the_shape_and_residuals(dome: Path) -> None:
    entities = rrd_entities(dome / "s.rrd")
    assert {"/scene/shape", "/scene/residual", "/scene/phantom", "/scene/tip"} <= set(entities)


def _lift(tsv: Path, marker: str, mm: float) -> None:
    """Move one marker of a QTM 3D export ``mm`` up (its Z column) in every frame."""
    lines = tsv.read_text().splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("Frame\t"))
    col = lines[head].split("\t").index(f"{marker} Z")
    for i in range(head + 1, len(lines)):
        cells = lines[i].split("\t")
        if cells[col]:
            cells[col] = f"{float(cells[col]) + mm:.3f}"
        lines[i] = "\t".join(cells)
    tsv.write_text("\n".join(lines) + "\n")


def test_a_marker_off_the_mould_is_refused(dome: Path, tmp_path: Path) -> None:
    import shutil

    session = tmp_path / "s"
    shutil.copytree(dome / "s", session)
    _lift(session / "indentation.tsv", "P12", 3.0)
    run_ingest(session, tmp_path / "s.mcap")
    out = tmp_path / "s.h5"
    res = CliRunner().invoke(cli, ["-q", "sync", str(tmp_path / "s.mcap"), "--out", str(out)])
    assert res.exit_code == 2
    line = res.stderr.strip()
    assert "\n" not in line and "P12" in line and "off the registered shape" in line
    assert not out.exists() and not list(tmp_path.glob("s.h5*"))


@pytest.mark.parametrize("command", [("fit-msm", "STATES", "--out", "x.json"),
                                     ("fit-solid", "STATES", "--out", "x.json"),
                                     ("simulate", "--layout", "STATES", "--out", "x.h5")])
def test_flat_simulators_refuse_curved_states(dome: Path, tmp_path: Path, command) -> None:
    """The MSM and the solid model simulate a flat block: a curved phantom's states (in its
    shape's frame) are refused in one line, nothing written."""
    args = [str(dome / "states.h5") if a == "STATES" else str(tmp_path / a) if "." in a else a
            for a in command]
    res = CliRunner().invoke(cli, ["-q", *args])
    assert res.exit_code == 2, res.output
    line = res.stderr.strip()
    assert "\n" not in line and "curved phantom" in line and "flat block" in line
    assert not list(tmp_path.iterdir())


def test_a_mould_file_the_twin_was_not_built_around(tmp_path: Path) -> None:
    """A half-cylinder lying on its flat face, written as an OBJ: registered and measured
    against its truth as the dome is."""
    from benchmarks.bench_curved import write_half_cylinder

    mould = write_half_cylinder(tmp_path / "half_cylinder.obj")
    run_synth(None, tmp_path / "s", SynthParams(seed=2, locations=2, repeats=1,
                                                 shape=str(mould)))
    run_ingest(tmp_path / "s", tmp_path / "s.mcap")
    run_sync(tmp_path / "s.mcap", tmp_path / "s.h5")
    curved = curved_errors(tmp_path / "s.h5", tmp_path / "s" / "truth.h5")
    assert curved["residual_max_mm"] < 0.3 and curved["frame_mm"] < 0.1
    assert curved["depth_rms_mm"] < 0.2


def test_the_solid_of_the_mould_fits_and_presses_the_dome(dome: Path, tmp_path: Path) -> None:
    """fit-solid with the session (its shape) meshes the dome and fits its presses closer than
    a still surface; simulate --solid presses it at the lab's markers, in the shape's frame."""
    solid, out = tmp_path / "solid.json", tmp_path / "solid_states.h5"
    fit = CliRunner().invoke(cli, ["-q", "fit-solid", str(dome / "states.h5"), "--session",
                                   str(dome / "s"), "--spacing-mm", "10", "--layers", "4",
                                   "--out", str(solid), "--no-rrd"])
    assert fit.exit_code == 0, fit.output
    doc = json.loads(solid.read_text())
    assert "shape" in doc["block"]
    assert doc["distances_mm"]["solid"] < 0.8 * doc["distances_mm"]["still"]
    sim = CliRunner().invoke(cli, ["-q", "simulate", "--solid", str(solid), "--layout",
                                   str(dome / "states.h5"), "--locations", "2", "--directions",
                                   "2", "--out", str(out), "--no-rrd"])
    assert sim.exit_code == 0, sim.output
    with h5py.File(out) as f, h5py.File(dome / "states.h5") as lab:
        rest = f["states/points"][0][:-1]
        np.testing.assert_allclose(rest, np.nanmedian(
            lab["states/points"][()][lab["states/step"][()] == 0][:, :-1], axis=0), atol=1e-6)


@pytest.mark.parametrize("mould, what", [(b"solid junk\nnot a facet\n", "not a surface mesh"),
                                         (None, "does not exist")])
def test_a_bad_mould_is_refused_at_ingest(dome: Path, tmp_path: Path, mould, what) -> None:
    import shutil

    session = tmp_path / "s"
    shutil.copytree(dome / "s", session)
    if mould is None:
        (session / "mould.stl").unlink()
    else:
        (session / "mould.stl").write_bytes(mould)
    out = tmp_path / "s.mcap"
    res = CliRunner().invoke(cli, ["-q", "ingest", str(session), "--out", str(out)])
    assert res.exit_code == 2
    line = res.stderr.strip()
    assert "\n" not in line and what in line and "mould.stl" in line
    assert not list(tmp_path.glob("s.mcap*"))


def test_a_press_that_never_touches_the_mould_is_refused() -> None:
    """A tip that stays 10 mm above the dome while the force rises (a press on something
    else) is refused by its number."""
    from calib.shape_registration import Registration
    from core.errors import BadInput
    from sim.twin.twin_shape import dome as dome_shape
    from sync.presses import Press
    from sync.surface import shape_depth, shape_touches

    shape = dome_shape((0.1, 0.1, 0.032), 0.03, "dome:30").shape
    reg = Registration(np.eye(4), np.zeros(25))
    tip = np.tile([0.05, 0.05, 0.04], (40, 1))              # the apex is at z = 30 mm
    press = Press(onset=10, peak=20, release=30)
    with pytest.raises(BadInput, match="press 0 .*never touches"):
        shape_touches(tip, shape_depth(tip, reg, shape), [press], reg, shape, "s.tsv")


def test_a_press_is_touched_where_it_began_not_at_the_press_before() -> None:
    """A tip that presses the apex, slides inside the dome to its flank and presses again
    there without leaving it: the second press's touch is on the flank (its onset moved onto
    the surface), never the first press's crossing."""
    from calib.shape_registration import Registration
    from sim.twin.twin_shape import dome as dome_shape
    from sync.presses import Press
    from sync.surface import shape_depth, shape_touches

    shape = dome_shape((0.1, 0.1, 0.032), 0.03, "dome:30").shape
    reg = Registration(np.eye(4), np.zeros(25))
    apex, flank = np.array([0.05, 0.05, 0.03]), np.array([0.075, 0.05, 0.0])
    flank[2] = shape.height(flank[None, :2])[0]
    path = [apex + [0, 0, 0.01 - 0.001 * k] for k in range(20)]          # down through 0
    path += [apex + [0, 0, -0.01]] * 20                                   # the first press
    path += [apex + (flank - apex) * s + [0, 0, -0.01] for s in np.linspace(0, 1, 40)]
    path += [flank + [0, 0, -0.004]] * 20                                 # the second
    tip = np.array(path)
    presses = [Press(onset=12, peak=30, release=40), Press(onset=82, peak=90, release=100)]
    at, _ = shape_touches(tip, shape_depth(tip, reg, shape), presses, reg, shape, "s.tsv")
    assert np.linalg.norm(at[0] - apex) < 0.2e-3
    assert np.linalg.norm(at[1, :2] - flank[:2]) < 3e-3

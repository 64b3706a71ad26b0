"""`pipeline synth`'s other labs: marker grids and scattered layouts, footprints and mocap rates,
each checked against the twin's own truth (and the frame extract builds from session.toml).

Sessions are short (one or two short presses, a 2 s pivot) so that each test takes seconds.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from data_schema.hdf5 import validate_h5
from data_schema.session import read_session
from data_schema.truth import TRUTH
from ingest.qtm_3d import read_qtm_3d
from ingest.qtm_6d import read_qtm_6d
from pipeline.cli import cli
from sim.twin.phantom import Phantom
from sim.twin.synth_stage import phantom_spec

SHORT = ["--repeats", "1", "--press-seconds", "3", "--pivot-seconds", "2", "--no-rrd"]
TOP_M = 0.032 + 0.0015          # marker centres: 1.5 mm above the 32 mm block's top


def run(args: list[str]):
    return CliRunner().invoke(cli, ["-q", *args])


def synth(folder: Path, *args: str) -> Path:
    res = run(["synth", str(folder), *SHORT, *args])
    assert res.exit_code == 0, res.output
    return folder


def truth(folder: Path) -> dict[str, np.ndarray]:
    with h5py.File(folder / "truth.h5", "r") as f:
        out = {k: f[k][()] for k in ("phantom/rest_points", "phantom/to_lab", "point_names",
                                      "mocap/points", "mocap/time_s", "mocap/visible",
                                      "states/points", "locations/contact",
                                      "presses/times_s")}
        out["rate_hz"] = f.attrs["rate_hz"]
    return out


def in_phantom(t: dict, lab: np.ndarray) -> np.ndarray:
    """Lab points in the twin's phantom frame (bottom centre of the block, z up)."""
    to_lab = t["phantom/to_lab"]
    return (lab - to_lab[:3, 3]) @ to_lab[:3, :3]


def session(folder: Path) -> dict:
    return tomllib.loads((folder / "session.toml").read_text())


@pytest.fixture(scope="module")
def grid6(tmp_path_factory) -> Path:
    """A 36-marker lab: 6 x 6 markers 12 mm apart, mocap at 300 Hz."""
    return synth(tmp_path_factory.mktemp("layouts") / "grid6", "--markers", "6x6",
                 "--marker-pitch", "12", "--mocap-rate", "300", "--locations", "2", "--seed", "5")


@pytest.fixture(scope="module")
def scattered(tmp_path_factory) -> Path:
    """A 150 x 80 mm block with 20 markers at random nodes."""
    return synth(tmp_path_factory.mktemp("layouts") / "scattered", "--markers", "scattered:20",
                 "--size", "150x80", "--locations", "2", "--seed", "5")


def test_36_markers_form_a_6x6_grid_12mm_apart_on_the_top(grid6: Path) -> None:
    t = truth(grid6)
    names = [n.decode() if isinstance(n, bytes) else n for n in t["point_names"]]
    assert names == [f"P{k:02d}" for k in range(36)] + ["tip"]
    rest = in_phantom(t, t["phantom/rest_points"])
    np.testing.assert_allclose(rest[:, 2], TOP_M, atol=1e-9)
    grid = rest[:, :2].reshape(6, 6, 2)                  # row-major: rows along +x, P00 first
    np.testing.assert_allclose(np.diff(grid[..., 0], axis=1), 0.012, atol=1e-9)
    np.testing.assert_allclose(np.diff(grid[..., 1], axis=1), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.diff(grid[..., 1], axis=0), 0.012, atol=1e-9)
    np.testing.assert_allclose(rest[:, :2].mean(axis=0), 0.0, atol=1e-9)   # centred
    assert t["mocap/points"].shape[1:] == (37, 3) and t["states/points"].shape[1:] == (37, 3)
    assert t["mocap/visible"].shape[1] == 40
    validate_h5(grid6 / "truth.h5", TRUTH)


def test_36_markers_in_every_lab_file_and_session_toml(grid6: Path) -> None:
    s = session(grid6)
    assert s["mocap"]["phantom_markers"] == [f"P{k:02d}" for k in range(36)]
    assert s["phantom"] == {"size_mm": [100.0, 100.0]}      # a square grid, centred: no more
    cfg = read_session(grid6)
    assert len(cfg.mocap.phantom_markers) == 36 and cfg.phantom.size_m == (0.1, 0.1)
    m = read_qtm_3d(grid6 / "indentation.tsv")
    assert m.labels[:36] == s["mocap"]["phantom_markers"] and len(m.labels) == 40


def test_300_hz_mocap_and_a_1_khz_logger(grid6: Path) -> None:
    t = truth(grid6)
    m = read_qtm_3d(grid6 / "indentation.tsv")
    assert m.rate_hz == 300 and t["rate_hz"] == 300
    steps = np.diff(m.time_ns) * 1e-9
    np.testing.assert_allclose(steps, 1 / 300, atol=1e-5)        # Time column, 5 decimals
    assert len(m.time_ns) == len(t["mocap/time_s"])
    np.testing.assert_allclose(m.time_ns * 1e-9, t["mocap/time_s"], atol=6e-6)
    body = read_qtm_6d(grid6 / "indentation_6D.tsv")
    assert body.rate_hz == 300 and len(body.time_ns) == len(m.time_ns)
    with open(grid6 / "force.csv") as f:
        f.readline()
        t0, t1 = (float(f.readline().split(",")[0]) for _ in range(2))
    assert t1 - t0 == pytest.approx(1e-3)


def test_the_rate_changes_no_press(grid6: Path, tmp_path: Path) -> None:
    """The same seed at 500 Hz presses the same places at the same times: durations are in
    seconds, not frames."""
    at500 = synth(tmp_path / "g500", "--markers", "6x6", "--marker-pitch", "12",
                  "--locations", "2", "--seed", "5")
    a, b = truth(grid6), truth(at500)
    np.testing.assert_array_equal(a["presses/times_s"], b["presses/times_s"])
    np.testing.assert_array_equal(a["locations/contact"], b["locations/contact"])
    assert len(b["mocap/time_s"]) / len(a["mocap/time_s"]) == pytest.approx(5 / 3, rel=1e-3)


def test_scattered_markers_keep_spacing_and_margin_and_no_rows(scattered: Path) -> None:
    t = truth(scattered)
    rest = in_phantom(t, t["phantom/rest_points"])
    assert rest.shape == (20, 3)
    np.testing.assert_allclose(rest[:, 2], TOP_M, atol=1e-9)
    gaps = np.linalg.norm(rest[:, None, :2] - rest[None, :, :2], axis=2)
    assert gaps[~np.eye(20, dtype=bool)].min() >= 0.010 - 1e-9
    assert np.all(np.abs(rest[:, 0]) <= 0.075 - 0.010 + 1e-9)
    assert np.all(np.abs(rest[:, 1]) <= 0.040 - 0.010 + 1e-9)
    # not a grid: no split into equal rows of a common y
    ys = np.unique(np.round(rest[:, 1], 6))
    counts = [np.sum(np.isclose(rest[:, 1], y)) for y in ys]
    assert len(ys) >= 5 and len(set(counts)) > 1
    # P00 -> P01 runs along the block's +x, at least half the usable length
    assert rest[0, 1] == pytest.approx(rest[1, 1], abs=1e-12)
    assert rest[1, 0] - rest[0, 0] >= 0.5 * (0.150 - 0.020) - 1e-9
    # presses inside the footprint, 20 mm from its edges
    contact = in_phantom(t, t["locations/contact"])
    assert np.all(np.abs(contact[:, 0]) <= 0.055 + 1e-9)
    assert np.all(np.abs(contact[:, 1]) <= 0.020 + 1e-9)


def test_scattered_session_names_its_axis_and_anchor(scattered: Path) -> None:
    t = truth(scattered)
    rest = in_phantom(t, t["phantom/rest_points"])
    s = session(scattered)
    assert s["mocap"]["phantom_markers"] == [f"P{k:02d}" for k in range(20)]
    table = s["phantom"]
    assert table["size_mm"] == [150.0, 80.0] and table["x_axis"] == ["P00", "P01"]
    assert table["anchor"] == "P00" and "rows" not in table
    # the anchor is P00's true place on the footprint [0, 150] x [0, 80] mm
    np.testing.assert_allclose(table["anchor_mm"], rest[0, :2] * 1e3 + [75.0, 40.0], atol=1e-6)
    layout = read_session(scattered).phantom
    assert layout.x_axis == ("P00", "P01") and layout.anchor == "P00"
    assert layout.size_m == pytest.approx((0.15, 0.08))


def test_scattered_layout_is_seeded() -> None:
    def nodes(seed: int) -> np.ndarray:
        return Phantom(phantom_spec("scattered:20", size="150x80", seed=seed)).marker_ij
    assert np.array_equal(nodes(5), nodes(5))
    assert not np.array_equal(nodes(5), nodes(6))


@pytest.mark.parametrize("markers, pitch, size, rows", [
    ("6x6", "12", "100x100", None), ("4x6", "15", "150x80", 4),
    ("scattered:20", "20", "150x80", None)])
def test_extracts_frame_from_session_toml_puts_markers_where_they_are(
        tmp_path: Path, markers: str, pitch: str, size: str, rows: int | None) -> None:
    """session.toml's [phantom] and the rest markers give extract's phantom frame: every
    marker lands on its true place on the footprint [0, L] x [0, W] (z = 0: the marker
    plane), and +x is the block's x."""
    from extract.phantom_frame import apply_transform, to_phantom_frame

    folder = synth(tmp_path / "s", "--markers", markers, "--marker-pitch", pitch,
                   "--size", size, "--locations", "1", "--seed", "2")
    t = truth(folder)
    cfg = read_session(folder)
    assert cfg.phantom.rows == rows
    lab = t["phantom/rest_points"]
    normal = t["phantom/to_lab"][:3, 2]
    frame = to_phantom_frame(lab, cfg.mocap.phantom_markers, lab[0], normal, cfg.phantom)
    got = apply_transform(frame, lab)
    true = in_phantom(t, lab)[:, :2] + np.array(cfg.phantom.size_m) / 2
    np.testing.assert_allclose(got[:, :2], true, atol=1e-9)
    np.testing.assert_allclose(got[:, 2], 0.0, atol=1e-9)


def test_analog_force_refuses_a_rate_that_does_not_divide_1000(tmp_path: Path) -> None:
    out = tmp_path / "a"
    res = run(["synth", str(out), *SHORT, "--locations", "1", "--force-via", "analog",
               "--mocap-rate", "300"])
    assert res.exit_code == 2, res.output
    line = res.output.strip()
    assert "\n" not in line and "--mocap-rate" in line and "300 Hz" in line
    assert not out.exists() or not any(out.iterdir())


def test_analog_force_at_250_hz_has_four_samples_a_frame(tmp_path: Path) -> None:
    folder = synth(tmp_path / "a", "--locations", "1", "--force-via", "analog",
                   "--mocap-rate", "250", "--markers", "2x3", "--marker-pitch", "30")
    s = session(folder)
    assert s["phantom"] == {"size_mm": [100.0, 100.0], "rows": 2}
    frames = len(truth(folder)["mocap/time_s"])
    with h5py.File(folder / "truth.h5") as f:
        samples = len(f["logger/time_s"])
    assert samples == 4 * frames


@pytest.mark.parametrize("args, option", [
    (["--markers", "1x5"], "--markers"),
    (["--markers", "five"], "--markers"),
    (["--markers", "scattered:3"], "--markers"),
    (["--markers", "scattered:200"], "--markers"),
    (["--markers", "8x8", "--marker-pitch", "20"], "--markers"),
    (["--marker-pitch", "6"], "--marker-pitch"),
    (["--size", "150"], "--size"),
    (["--size", "20x20"], "--size"),
    (["--mocap-rate", "0"], "--mocap-rate"),
])
def test_impossible_layouts_are_refused_in_one_line(tmp_path: Path, args: list[str],
                                                    option: str) -> None:
    out = tmp_path / "bad"
    res = run(["synth", str(out), *SHORT, "--locations", "1", *args])
    assert res.exit_code == 2, res.output
    line = res.output.strip()
    assert "\n" not in line and line.startswith((f"error: {option}:", f"error: {option} ")), line
    assert not out.exists() or not any(out.iterdir())


def found_states(states: Path, truth_file: Path) -> tuple[float, np.ndarray, float]:
    """Share of truth's 0.5 N states extract found (same press, same level), each found
    state's mean point distance from the truth (m, truth moved into extract's frame), and
    the largest in-plane distance (m) between each marker's rest place in extract's frame
    and on the twin's footprint."""
    from extract.phantom_frame import apply_transform

    with h5py.File(states) as s, h5py.File(truth_file) as t:
        seq, step = s["states/sequence"][()], s["states/step"][()]
        pts, valid = s["states/points"][()], s["states/valid"][()]
        frame, size = s["sessions/transform"][0], s.attrs["footprint_m"]
        t_pts, t_step, t_press = t["states/points"][()], t["states/step"][()], t["states/press"][()]
        to_lab, rest = t["phantom/to_lab"][()], t["phantom/rest_points"][()]
    dist = []
    for p, k, true in zip(t_press, t_step, t_pts, strict=True):
        i = np.flatnonzero((seq == p) & (step == k))
        if i.size:
            v = valid[i[0]]
            dist.append(np.linalg.norm(pts[i[0]][v] - apply_transform(frame, true)[v],
                                       axis=1).mean())
    ours = apply_transform(frame, rest)[:, :2]
    twin = apply_transform(np.linalg.inv(to_lab), rest)[:, :2] + np.asarray(size) / 2
    return len(dist) / len(t_step), np.array(dist), float(np.abs(ours - twin).max())


@pytest.mark.parametrize("lab", ["grid6", "scattered"])
def test_ingest_sync_extract_meet_the_targets_on_other_labs(request, lab: str,
                                                            tmp_path: Path) -> None:
    """36 markers at 300 Hz, and 20 scattered markers on a 150 x 80 mm block, through
    ingest, sync and extract: the clock, the tip and the 0.5 N states to sync's targets
    (offset <= 0.5 ms, tip <= 0.25 mm RMS, >= 90 % of the states at <= 0.15 mm mean)."""
    from sync.sync_accuracy import TARGETS, sync_errors

    folder: Path = request.getfixturevalue(lab)
    mcap, synced, states = tmp_path / "s.mcap", tmp_path / "s.h5", tmp_path / "states.h5"
    for args in (["ingest", folder, "--out", mcap], ["sync", mcap, "--out", synced],
                 ["extract", synced, "--out", states]):
        res = run([*map(str, args), "--no-rrd"])
        assert res.exit_code == 0, res.output
    err = sync_errors(synced, folder / "truth.h5")
    assert err["clock_offset_ms"] <= TARGETS["clock_offset_ms"]
    assert err["tip_rms_mm"] <= TARGETS["tip_rms_mm"]
    assert err["presses_missed"] == err["presses_extra"] == 0
    found, dist, frame_m = found_states(states, folder / "truth.h5")
    assert found >= 0.9 and dist.mean() <= 0.15e-3
    assert frame_m < 0.1e-3                 # extract's frame puts the markers where they are
    with h5py.File(states) as s:
        names = json.loads(s.attrs["point_names"])
    assert names == session(folder)["mocap"]["phantom_markers"] + ["tip"]


def per_frame(rrd: Path, entity: str, component: str) -> list[int]:
    """How many instances of ``component`` each temporal row of ``entity`` holds."""
    from rerun.chunk import RrdReader

    sizes: list[int] = []
    for chunk in RrdReader(str(rrd)).store().stream():
        if chunk.entity_path == entity and not chunk.is_static:
            col = chunk.to_record_batch().column(component)
            sizes += [len(col[i]) for i in range(len(col))]
    return sizes


def test_recording_shows_the_layout_as_it_is(tmp_path: Path) -> None:
    """A 2 x 3 grid: six true markers in every frame of the recording (not 25), the measured
    ones among them, the indenter's 4 apart."""
    folder = tmp_path / "s"
    res = run(["synth", str(folder), *SHORT[:-1], "--locations", "1", "--markers", "2x3",
               "--marker-pitch", "30"])
    assert res.exit_code == 0, res.output
    rrd = folder / "recording.rrd"
    truth_boxes = per_frame(rrd, "/truth/markers", "Boxes3D:centers")
    measured = per_frame(rrd, "/measured/markers", "Points3D:positions")
    cluster = per_frame(rrd, "/measured/cluster", "Points3D:positions")
    assert truth_boxes and set(truth_boxes) == {6}
    assert max(measured) == 6 and max(cluster) == 4


def test_truth_readers_take_any_1x_version(scattered: Path, tmp_path: Path) -> None:
    """A 1.x file has any N; a 1.0 file (25 markers) reads, a 2.0 one is refused."""
    from core.errors import BadInput

    copy = tmp_path / "truth.h5"
    copy.write_bytes((scattered / "truth.h5").read_bytes())
    with h5py.File(scattered / "truth.h5") as f:
        assert f.attrs["schema_version"] == TRUTH.version == "1.2"
    for version, ok in (("1.0", True), ("1.7", True), ("2.0", False)):
        with h5py.File(copy, "r+") as f:
            f.attrs["schema_version"] = version
        if ok:
            validate_h5(copy, TRUTH)
        else:
            with pytest.raises(BadInput, match="not compatible"):
                validate_h5(copy, TRUTH)

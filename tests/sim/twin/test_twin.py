"""`pipeline synth`: the phantom twin's session folder against its own truth.

Small sessions (one location, two short presses) keep the file fast; the default-size session
and the paper's Table-1 depths are a slow test.
"""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from core.recording import rrd_entities, rrd_has_blueprint, rrd_timelines
from data_schema.hdf5 import validate_h5
from data_schema.session import read_session
from data_schema.truth import TRUTH
from ingest.ati_cal import read_ati_cal
from ingest.force_log import read_force_log
from ingest.qtm_3d import read_qtm_3d
from ingest.qtm_6d import read_qtm_6d
from pipeline.cli import cli
from sim.twin.indenter import HandStyle, plan_hand
from sim.twin.nano17 import FILE_TO_SI, Nano17

TINY = ["--locations", "1", "--repeats", "2", "--press-seconds", "3", "--pivot-seconds", "5"]
DATA_FILES = ("indentation.tsv", "indentation_6D.tsv", "pivot.tsv", "force.csv", "force.mat",
              "session.toml")
GAUGES = [f"G{k}" for k in range(6)]


def run(args: list[str]):
    return CliRunner().invoke(cli, ["-q", *args])


def synth(folder: Path, *args: str) -> Path:
    res = run(["synth", str(folder), *TINY, *args])
    assert res.exit_code == 0, res.output
    return folder


@pytest.fixture(scope="module")
def skewed(tmp_path_factory) -> Path:
    """A tiny session with a large clock offset and drift (measurable in a few seconds)."""
    return synth(tmp_path_factory.mktemp("twin") / "skewed", "--seed", "7", "--offset",
                 "-1.25", "--drift", "400")


@pytest.fixture(scope="module")
def plain(tmp_path_factory) -> Path:
    """A tiny session with the clock drawn from the seed, no recording."""
    return synth(tmp_path_factory.mktemp("twin") / "plain", "--seed", "11", "--no-rrd")


def truth(folder: Path) -> h5py.File:
    return h5py.File(folder / "truth.h5", "r")


def force_log(folder: Path):
    return read_force_log(folder / "force.csv", "time", GAUGES, trigger_column="trigger")


def calibrated(folder: Path) -> np.ndarray:
    """The logged wrench with the .cal read back and the true (creeping) bias."""
    log = force_log(folder)
    cal = read_ati_cal(next(folder.glob("FT*.cal")))
    with truth(folder) as t:
        sensor = Nano17(serial=cal.serial, matrix=cal.matrix / FILE_TO_SI[:, None],
                        bias=t["calibration/bias"][()],
                        bias_drift=t["calibration/bias_drift"][()],
                        quantum=float(t["calibration/quantum"][()]),
                        noise=float(t["calibration/noise"][()]))
    return sensor.wrench(log.values, log.time_ns * 1e-9)


def test_session_folder_parses_and_truth_validates(skewed: Path) -> None:
    cfg = read_session(skewed)
    assert cfg.mocap.phantom_markers == [f"P{k:02d}" for k in range(25)]
    assert len(cfg.mocap.indenter_markers) == 4
    assert cfg.mocap.trigger_event == "Trigger" and cfg.force.trigger_column == "trigger"
    assert cfg.force.calibration is not None and cfg.pivot_file is not None
    # the paper's phantom: 100 x 100 mm, a square grid centred on it (no axis, no anchor)
    assert cfg.raw["phantom"] == {"size_mm": [100.0, 100.0]}
    assert cfg.phantom.size_m == (0.1, 0.1) and cfg.phantom.x_axis is None
    validate_h5(skewed / "truth.h5", TRUTH)
    head = (skewed / "indentation.tsv").read_bytes()[:4000].decode()
    assert "TRAJECTORY_TYPES\tMeasured" in head and "\r\nFrame\tTime\tP00 X\tP00 Y" in head
    assert "\tIndenter - 4 Z\t\r\n" in head and "EVENT\tTrigger\t" in head


def test_marker_noise_has_the_papers_residual(plain: Path) -> None:
    m = read_qtm_3d(plain / "indentation.tsv")
    with truth(plain) as t:
        true = np.concatenate([t["mocap/points"][:, :25], t["mocap/cluster"][()]], axis=1)
        visible = t["mocap/visible"][()]
    err = np.linalg.norm(m.positions - true, axis=2) * 1e3           # mm
    assert np.array_equal(np.isfinite(err), visible)                 # gaps exactly as planned
    assert 0.17 < err[visible].mean() < 0.19
    assert 0.20 < err[visible].std() < 0.24
    assert 0 < (~visible).mean() < 0.05


def test_gaps_gather_near_the_indenter(plain: Path) -> None:
    with truth(plain) as t:
        visible, press = t["mocap/visible"][()], t["mocap/press"][()]
        rest, contact = t["phantom/rest_points"][()], t["locations/contact"][0]
    pressing = press >= 0
    near = np.linalg.norm(rest[:, :2] - contact[:2], axis=1) < 0.025
    missing_near = 1 - visible[pressing][:, :25][:, near].mean()
    missing_far = 1 - visible[:, :25][:, ~near].mean()
    assert missing_near > 5 * missing_far
    assert 1 - visible[:, 25:].mean() > missing_far


def test_clock_offset_and_drift_as_asked(skewed: Path) -> None:
    log = force_log(skewed)
    t_f = log.time_ns * 1e-9
    with truth(skewed) as t:
        offset, drift = t["clock/offset_s"][()], t["clock/drift_ppm"][()]
        pulses = t["trigger/mocap_time_s"][()]
        frame_t, magnitude = t["mocap/time_s"][()], t["force/magnitude"][()]
    assert offset == -1.25 and drift == 400.0
    # rising edges of the logged trigger: one sample (1 ms) after t_f = offset + (1+d) t_m
    hi = log.trigger > 2.5
    edges = t_f[np.flatnonzero(hi[1:] & ~hi[:-1]) + 1]
    assert len(edges) == len(pulses) >= 4
    lag = edges - (offset + (1 + drift * 1e-6) * pulses)
    assert np.all((lag >= 0) & (lag < 1e-3 + 1e-9))
    # (1 ms edges over ~8 s of pulses pin the drift only to ~+-50 ppm; the force does better)
    # the force series: the log, put on the mocap clock with the convention, is the true force
    measured = np.linalg.norm(calibrated(skewed)[:, :3], axis=1)
    t_m = (t_f - offset) / (1 + drift * 1e-6)
    inside = (t_m > 0) & (t_m < frame_t[-1])
    expected = np.interp(t_m[inside], frame_t, magnitude)
    assert magnitude.max() > 2.0
    assert np.abs(measured[inside] - expected).max() < 0.06      # noise, tool weight, tremor
    wrong = np.interp(t_m[inside] + 0.05, frame_t, magnitude)     # 50 ms off is visibly off
    assert np.abs(measured[inside] - wrong).max() > 0.2


def test_force_log_pins_the_drift_within_a_few_ppm(skewed: Path) -> None:
    """Without the tool's weight the logged force differs from the truth only by the
    Nano17's noise (~1/320 N), and the load ramps (~5 N/s) time it to ~20 us per ramp: over
    the ~6 s between the presses that fixes the drift to a few ppm."""
    log = force_log(skewed)
    t_f = log.time_ns * 1e-9
    with truth(skewed) as t:
        offset, drift = t["clock/offset_s"][()], t["clock/drift_ppm"][()]
        frame_t, on_tip = t["mocap/time_s"][()], t["force/sensor"][()]
        contact = calibrated(skewed)[:, :3] - t["logger/tool_force"][()]

    def misfit(ppm: float) -> float:
        t_m = (t_f - offset) / (1 + ppm * 1e-6)
        inside = (t_m > 0) & (t_m < frame_t[-1])
        expected = np.stack([np.interp(t_m[inside], frame_t, on_tip[:, a]) for a in range(3)],
                            axis=1)
        return float(np.mean((contact[inside] - expected) ** 2))

    ppm = drift + np.arange(-40.0, 40.5, 0.5)
    best = ppm[np.argmin([misfit(d) for d in ppm])]
    assert abs(best - drift) <= 5.0


def test_drawn_clock_and_a_log_that_covers_the_mocap(plain: Path) -> None:
    log = force_log(plain)
    t_f = log.time_ns * 1e-9
    with truth(plain) as t:
        offset, drift = t["clock/offset_s"][()], t["clock/drift_ppm"][()]
        end = t["mocap/time_s"][-1]
        noise = t["calibration/noise"][()]
        true = t["logger/force"][()] + t["logger/tool_force"][()]
    assert 0.3 <= abs(offset) <= 3.0 and 10.0 <= abs(drift) <= 60.0
    assert t_f[0] < offset - 1.0 and t_f[-1] > offset + (1 + drift * 1e-6) * end + 0.4
    assert np.allclose(np.diff(t_f), 1e-3)
    # the log starts still and unloaded (a tare is possible), and the gauges carry a bias
    first = log.values[: 1000]
    assert np.all(first.std(axis=0) < 3 * noise)
    assert np.all(np.abs(first.mean(axis=0)) > 0.03)
    # Nano17 resolution: the calibrated force is the truth within a few 1/320 N
    error = calibrated(plain)[:, :3] - true
    assert np.all(error.std(axis=0) < 3 / 320) and np.abs(error).max() < 0.03


def test_same_seed_same_bytes(plain: Path, tmp_path: Path) -> None:
    again = synth(tmp_path / "again", "--seed", "11", "--no-rrd")
    other = synth(tmp_path / "other", "--seed", "12", "--no-rrd")
    cal = next(plain.glob("FT*.cal")).name
    for name in (*DATA_FILES, cal):
        assert (plain / name).read_bytes() == (again / name).read_bytes(), name
    assert (plain / "indentation.tsv").read_bytes() != (other / "indentation.tsv").read_bytes()
    assert (plain / "force.csv").read_bytes() != (other / "force.csv").read_bytes()
    with truth(plain) as a, truth(again) as b:
        for name in ("mocap/points", "states/points", "logger/force", "clock/offset_s"):
            assert np.array_equal(a[name][()], b[name][()])


def test_giving_the_drawn_clock_changes_no_other_draw(plain: Path, tmp_path: Path) -> None:
    """The seed's own offset and drift, passed explicitly, give the same bytes."""
    with truth(plain) as t:
        offset, drift = float(t["clock/offset_s"][()]), float(t["clock/drift_ppm"][()])
    given = synth(tmp_path / "given", "--seed", "11", "--no-rrd", "--offset", repr(offset),
                  "--drift", repr(drift))
    cal = next(plain.glob("FT*.cal")).name
    for name in (*DATA_FILES, cal):
        assert (plain / name).read_bytes() == (given / name).read_bytes(), name


def test_synth_over_an_earlier_session_leaves_none_of_its_files(skewed: Path,
                                                                 plain: Path,
                                                                 tmp_path: Path) -> None:
    """Seed 7 with a recording, overwritten by seed 11 without one: the old sensor's .cal and
    the old recording go, the user's own files stay, the rest is seed 11's session."""
    folder = tmp_path / "reused"
    shutil.copytree(skewed, folder)
    (folder / "notes.txt").write_text("keep me")
    (folder / "FT21007.cal.bak").write_text("not the twin's")
    assert (folder / "recording.rrd").is_file() and (folder / "FT21007.cal").is_file()
    synth(folder, "--seed", "11", "--no-rrd")
    names = {f.name for f in folder.iterdir()}
    assert names == {f.name for f in plain.iterdir()} | {"notes.txt", "FT21007.cal.bak"}
    assert (folder / "notes.txt").read_text() == "keep me"
    for name in DATA_FILES:
        assert (folder / name).read_bytes() == (plain / name).read_bytes(), name


def test_peak_forces_are_a_truncated_normal_not_piled_at_the_bounds() -> None:
    """6.2 +- 1.4 N kept within 2.5..8 N by drawing again, not by clipping (which would pile
    ~10 % of the presses at exactly 8 N)."""
    style = HandStyle()
    hand = plan_hand(np.random.default_rng(0), [(0, k, np.zeros(3)) for k in range(400)],
                     style)
    fmax = np.array([p.fmax for p in hand.presses])
    assert np.all((fmax > 2.5) & (fmax < 8.0))
    assert len(np.unique(fmax)) == len(fmax)
    # truncated: ~1.4 % within 0.1 N of the top; clipped: another ~10 % exactly at 8 N
    assert np.mean(fmax > 7.9) < 0.05
    assert 5.8 < fmax.mean() < 6.1                        # truncated mean 5.95 N


def test_static_states_are_the_presses_at_every_half_newton(plain: Path) -> None:
    with truth(plain) as t:
        st = {k: t[f"states/{k}"][()] for k in ("points", "force", "step", "press", "time_s")}
        fmax, direction = t["presses/fmax"][()], t["presses/direction"][()]
        frame_t, points = t["mocap/time_s"][()], t["mocap/points"][()]
        rest = t["phantom/rest_points"][()]
    np.testing.assert_allclose(st["force"], 0.5 * st["step"])
    for k, f in enumerate(fmax):
        mine = st["press"] == k
        assert mine.sum() == int(np.floor(f / 0.5)) + 1
        np.testing.assert_allclose(st["points"][mine][0, :25], rest, atol=1e-12)
        depth = rest[:, 2].mean() - st["points"][mine][:, 25, 2]
        assert np.all(np.diff(depth) > 0)                     # deeper at every 0.5 N
        assert np.all(np.diff(st["time_s"][mine]) > 0)
        # the recorded truth passes through each state when the force reaches it
        for i in np.flatnonzero(mine):
            at = np.array([np.interp(st["time_s"][i], frame_t, points[:, 25, a])
                           for a in range(3)])
            assert np.linalg.norm(at - st["points"][i, 25]) < 2e-4
    assert np.all((fmax >= 2.5) & (fmax <= 8.0))
    assert np.all(np.degrees(np.arccos(-direction[:, 2])) <= 20.0)


def test_6d_export_is_the_cluster_fit(skewed: Path) -> None:
    b = read_qtm_6d(skewed / "indentation_6D.tsv")
    assert b.bodies == ["Indenter"] and b.rate_hz == 500
    with truth(skewed) as t:
        origin, rot = t["mocap/body_origin"][()], t["mocap/body_rotation"][()]
        visible = t["mocap/visible"][:, 25:]
    pos = b.positions[:, 0]
    found = np.isfinite(pos).all(axis=1)
    assert np.array_equal(found, visible.sum(axis=1) >= 3)
    assert np.linalg.norm(pos[found] - origin[found], axis=1).max() < 3e-3
    cos = (np.einsum("tij,tij->t", b.rotations[found, 0], rot[found]) - 1) / 2
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 6.0


def test_pivot_recording_swings_about_the_tip(skewed: Path) -> None:
    p = read_qtm_3d(skewed / "pivot.tsv")
    with truth(skewed) as t:
        point, cluster = t["pivot/point"][()], t["pivot/cluster"][()]
        markers, tip = t["indenter/markers"][()], t["indenter/tip"][()]
        rot = t["pivot/rotation"][()]
    assert p.labels == [f"Indenter - {k}" for k in range(1, 5)] and p.frames == 2500
    np.testing.assert_allclose(np.linalg.norm(cluster - point, axis=2),
                               np.broadcast_to(np.linalg.norm(markers - tip, axis=1),
                                               cluster.shape[:2]), atol=1e-12)
    tilt = np.degrees(np.arccos(rot[:, 2, 2]))
    assert tilt.max() > 15.0
    err = np.linalg.norm(p.positions - cluster, axis=2)
    assert 0.1e-3 < np.nanmean(err) < 0.3e-3


def test_ingest_reads_the_session_as_written(skewed: Path, tmp_path: Path) -> None:
    from ingest.mcap_io import read_raw_mcap

    before = {f.name: hashlib.sha256(f.read_bytes()).hexdigest() for f in skewed.iterdir()}
    out = tmp_path / "skewed.mcap"
    res = run(["ingest", str(skewed), "--out", str(out), "--no-rrd"])
    assert res.exit_code == 0, res.output
    assert {f.name: hashlib.sha256(f.read_bytes()).hexdigest()
            for f in skewed.iterdir()} == before
    s = read_raw_mcap(out)
    with truth(skewed) as t:
        frames, samples = len(t["mocap/time_s"]), len(t["logger/time_s"])
        pulses = len(t["trigger/mocap_time_s"])
        matrix = t["calibration/matrix"][()]
    assert s.markers.frames == frames and len(s.markers.labels) == 29
    assert s.force.frames == samples and s.force.trigger is not None
    assert len([e for e in s.markers.events if e[0] == "Trigger"]) == pulses
    assert s.bodies is not None and s.pivot is not None and s.pivot.frames == 2500
    np.testing.assert_allclose(s.calibration.matrix, matrix, rtol=0, atol=1e-12)


def test_rerun_recording_shows_a_press_beside_its_truth(skewed: Path) -> None:
    rrd = skewed / "recording.rrd"
    found = rrd_entities(rrd)
    assert "Mesh3D" in found["/phantom/surface"]
    for entity in ("/truth/tip", "/measured/markers", "/measured/cluster", "/truth/states"):
        assert "Points3D" in found[entity], entity
    for entity in ("/truth/markers", "/truth/cluster"):      # cubes around the true points
        assert "Boxes3D" in found[entity], entity
    assert "LineStrips3D" in found["/truth/shaft"]
    for entity in ("/force/truth", "/force/measured", "/force/states"):
        assert "Scalars" in found[entity], entity
    assert "SeriesPoints" in found["/force/states"] and "SeriesLines" in found["/force/truth"]
    assert "ViewCoordinates" in found["/"] and rrd_timelines(rrd) == {"mocap_time"}
    assert rrd_has_blueprint(rrd)


def test_bad_options_and_foreign_folders(tmp_path: Path) -> None:
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("keep me")
    res = run(["synth", str(foreign), *TINY])
    assert res.exit_code == 2
    assert res.output.strip().splitlines() == [res.output.strip()]
    assert "not empty" in res.output
    assert sorted(p.name for p in foreign.iterdir()) == ["notes.txt"]
    res = run(["synth", str(tmp_path / "new"), *TINY, "--view-press", "5"])
    assert res.exit_code == 2 and "--view-press" in res.output
    assert not (tmp_path / "new").exists()


def test_inspect_reads_every_data_file(skewed: Path) -> None:
    for f in sorted(skewed.iterdir()):
        res = run(["inspect", str(f)])
        assert res.exit_code == 0, (f.name, res.output)


def test_force_mat_log_is_the_csv_log(plain: Path, tmp_path: Path) -> None:
    csv = force_log(plain)
    mat = read_force_log(plain / "force.mat", "time", GAUGES, trigger_column="trigger")
    assert np.array_equal(mat.time_ns, csv.time_ns)
    np.testing.assert_allclose(mat.values, csv.values, rtol=0, atol=5e-7)


@pytest.mark.slow
def test_default_session_is_fast_and_deep_like_the_paper(tmp_path: Path) -> None:
    from sim.twin.synth_stage import run_synth

    folder = run_synth(None, tmp_path / "default")      # its time: bench_twin.py
    with truth(folder) as t:
        points, press = t["states/points"][()], t["states/press"][()]
    single, multi = [], []
    for k in np.unique(press):
        p = points[press == k]
        for a in range(len(p)):
            for b in range(a + 1, len(p)):
                moved = np.linalg.norm(p[b] - p[a], axis=1).max() * 1e3
                (single if b == a + 1 else multi).append(moved)
    # the paper's Table 1 (experimental): multi-step max 30.3 mm, mean 8.9 mm;
    # single-step mean 2.4 mm
    assert 27.0 < max(multi) < 34.0
    assert 8.0 < np.mean(multi) < 12.5
    assert 1.6 < np.mean(single) < 2.9
    assert 200 < len(press) < 320


def test_rrd_naming_a_session_file_is_refused(tmp_path: Path) -> None:
    out = tmp_path / "s"
    res = run(["synth", str(out), *TINY, "--rrd", str(out / "truth.h5")])
    assert res.exit_code == 2 and "--rrd" in res.output, res.output
    assert not out.exists() or not any(out.iterdir())

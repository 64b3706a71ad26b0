"""The twin's force through a force plate (``pipeline synth --force-via plate``): QTM's
force-plate export of the true wrench, read by ingest as a wrench on the mocap's clock, synced
on that one clock and extracted, against the truth; what ingest refuses of it."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner
from helpers.spoiled_session import ingest_spoiled, replace_text
from helpers.staged_twin import shared_clock_checked, staged_twin
from helpers.truth_checks import check_states_against_truth

from core.force_plate import centre_of_pressure
from data_schema.session import read_session
from ingest.force_source import read_force
from ingest.qtm_force_plate import WRENCH, read_force_plate
from pipeline.cli import cli

PLATE_FILE = "indentation_f_1.tsv"


def _cli(*args: object):
    return CliRunner().invoke(cli, ["-q", *map(str, args)])


@pytest.fixture(scope="module")
def plate_session(tmp_path_factory) -> Path:
    """A twin session with the force from a plate under the phantom, ingested, synced and
    extracted."""
    return staged_twin(tmp_path_factory.mktemp("plate"), "--force-via", "plate")


def test_the_plate_export_is_the_true_wrench_on_the_mocap_clock(plate_session):
    """session.toml names the export as a wrench (no calibration, no Nano17's .cal); ingest
    reads N and N m on the mocap's clock, 2 samples a frame from the first frame; its force
    is the truth's contact force with the plate's few mN of noise, and its centre of pressure
    where the line of action meets the plate's top surface."""
    s = plate_session / "s"
    cfg = read_session(s)
    assert (cfg.force.file.name, cfg.force.kind, cfg.force.channels, cfg.force.calibration) \
        == (PLATE_FILE, "wrench", WRENCH, None)
    assert not list(s.glob("*.cal")) and not (s / "force.csv").exists()
    f = read_force(cfg.force)
    assert f.units == ["N", "N", "N", "N*m", "N*m", "N*m"] and f.meta["clock"] == "mocap"
    assert f.meta["plate"] == "Force-plate 1" and len(f.meta["plate_corners_mm"]) == 4
    with h5py.File(s / "truth.h5") as t:
        frames = len(t["mocap/time_s"])
        true_force, mocap_t = t["force/lab"][()], t["mocap/time_s"][()]
        offset, drift = t["clock/offset_s"][()], t["clock/drift_ppm"][()]
    assert (offset, drift) == (0, 0) and f.frames == 2 * frames and f.time_ns[0] == 0
    np.testing.assert_array_equal(f.time_ns[::2], np.round(mocap_t * 1e9).astype(np.int64))
    noise = f.values[::2, :3] - true_force                  # the plate frame is the lab's
    assert np.abs(noise.mean(axis=0)).max() < 5e-4 and np.abs(noise).max() < 0.04
    np.testing.assert_allclose(noise.std(axis=0), 0.005, rtol=0.05)
    table = read_force_plate(s / PLATE_FILE)
    cop = np.column_stack([table.columns[c] for c in ("COP_X", "COP_Y", "COP_Z")])
    loaded = np.abs(f.values[:, 2]) > 0.1
    np.testing.assert_allclose(cop[loaded], centre_of_pressure(
        f.values[loaded, :3], f.values[loaded, 3:]) * 1e3, atol=0.02)
    assert np.abs(cop[np.abs(f.values[:, 2]) > 1, :2]).max() < 60   # under the 100 mm phantom


def test_plate_route_shares_the_clock_and_meets_the_targets(plate_session):
    shared_clock_checked(plate_session)


def test_plate_route_states_against_truth(plate_session):
    check_states_against_truth(plate_session / "states.h5", plate_session / "s" / "truth.h5")


def _units_contradict(folder: Path) -> str:
    replace_text(folder / "session.toml", 'kind = "wrench"', 'kind = "wrench"\nunits = "kN"')
    return "channel 'Force_X' is in N as the file states, but force.units says kN"


def _rate_disagrees(folder: Path) -> str:
    replace_text(folder / "session.toml", "rate_hz = 1000.0", "rate_hz = 2000.0")
    return "force.rate_hz is 2000 Hz but the time column gives 1000 Hz"


@pytest.mark.parametrize("spoil", [_units_contradict, _rate_disagrees])
def test_bad_plate_input_is_one_line_exit_2_nothing_written(plate_session, tmp_path, spoil):
    line, said, folder = ingest_spoiled(plate_session / "s", tmp_path, spoil)
    assert line.startswith(f"error: {folder}/") and said in line, line


@pytest.mark.parametrize(("args", "words"), [
    (["--force-file", "c3d"], "--force-file: must be tsv with --force-via plate"),
    (["--offset", "1"], "--offset: --offset and --drift are the logger's clock"),
    (["--mocap-rate", "300"], "300 Hz does not divide the 1000 Hz force rate"),
])
def test_impossible_plate_sessions_are_refused(tmp_path, args, words):
    res = _cli("synth", tmp_path / "s", "--locations", "1", "--repeats", "1",
               "--force-via", "plate", "--no-rrd", *args)
    assert res.exit_code == 2 and words in res.stderr, res.stderr
    assert len(res.stderr.strip().splitlines()) == 1


def test_the_plate_route_replaces_the_analog_routes_files(tmp_path):
    """Written over an analog session, a plate session leaves neither the analog exports nor
    the Nano17's .cal."""
    folder = tmp_path / "s"
    for via, gone in (("analog", {PLATE_FILE}),
                      ("plate", {"indentation.c3d", "indentation_a.tsv"})):
        res = _cli("synth", folder, "--seed", "5", "--locations", "1", "--repeats", "1",
                   "--press-seconds", "2", "--pivot-seconds", "2", "--force-via", via,
                   "--no-rrd")
        assert res.exit_code == 0, res.output + res.stderr
        names = {p.name for p in folder.iterdir()}
        assert not names & gone and any(n.endswith(".cal") for n in names) == (via == "analog")

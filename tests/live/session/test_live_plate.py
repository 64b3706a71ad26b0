"""``pipeline live`` with the force from QTM's force component (a force plate under the
phantom, ``pipeline synth --force-via plate``) against the replay serving it as that plate:
the session it records is the session ingest reads from the plate's export, its states are
sync's and extract's, and what QTM's parameters contradict is refused before a frame, in one
line."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from helpers.live_replay import assert_same_states, offline_states, replaying

from core.errors import BadInput
from data_schema.session import read_session
from ingest.ingest_params import IngestParams
from ingest.ingest_stage import run_ingest
from ingest.mcap_io import read_raw_mcap
from live.protocol.parameters import ForcePlate, QtmParameters
from live.session.layout import live_layout, to_force
from live.session.live_params import LiveParams
from live.session.live_stage import MCAP_NAME, STATES_NAME, run_live
from pipeline.cli import cli
from sync.sync import sync_session

PLATE_FILE = "indentation_f_1.tsv"
SOURCE = "QTM RT 127.0.0.1:1"


@pytest.fixture(scope="module")
def recorded(plate_session: Path, tmp_path_factory: pytest.TempPathFactory):
    """The plate session recorded live from the replay, and the same session ingested."""
    out = tmp_path_factory.mktemp("plate_recorded") / "live"
    with replaying(plate_session) as server:
        summary = run_live(plate_session, out, LiveParams(port=server.port, timeout_s=10),
                           None)
        sent = server.stats.frames_sent
    ingested = out.parent / "ingested.mcap"
    run_ingest(plate_session, ingested, IngestParams(), None)
    return summary, sent, read_raw_mcap(out / MCAP_NAME), read_raw_mcap(ingested), out


def test_the_live_plate_session_is_the_ingested_session(recorded) -> None:
    """Every frame and force sample sent is recorded once; the markers to float32 mm, the
    plate's force and moment to float32, on the same clock, with the same channels, units,
    kind and plate as ingest reads from the export."""
    summary, sent, live, ingested, _ = recorded
    assert summary.ended == "QTM stopped playing the file"
    assert summary.counts.frames == sent == ingested.markers.frames
    assert summary.counts.samples == ingested.force.frames and summary.counts.skipped == 0
    lm, im = live.markers, ingested.markers
    np.testing.assert_array_equal(lm.time_ns, im.time_ns)
    np.testing.assert_allclose(lm.positions, im.positions, atol=1e-7, equal_nan=True)
    lf, inf = live.force, ingested.force
    np.testing.assert_array_equal(lf.time_ns, inf.time_ns)
    assert (lf.channels, lf.units, lf.kind, lf.rate_hz) == \
        (inf.channels, inf.units, inf.kind, inf.rate_hz) == \
        (inf.channels, ["N"] * 3 + ["N*m"] * 3, "wrench", 1000.0)
    for key in ("clock", "plate", "plate_type"):
        assert lf.meta[key] == inf.meta[key], key
    np.testing.assert_allclose(lf.meta["plate_corners_mm"], inf.meta["plate_corners_mm"],
                               atol=1e-3)
    np.testing.assert_array_equal(lf.values, np.float32(inf.values))
    assert live.calibration is None and ingested.calibration is None
    np.testing.assert_array_equal(live.pivot.positions, ingested.pivot.positions)


def test_presses_and_states_seen_live_are_the_offline_stages(recorded, tmp_path) -> None:
    summary, _, _, ingested, out = recorded
    assert summary.presses == len(sync_session(ingested).presses) == 4
    assert summary.states.startswith("43 states of 4 presses")
    assert_same_states(out / STATES_NAME, offline_states(out.parent / "ingested.mcap",
                                                         tmp_path / "offline"))


def _copy(session: Path, tmp_path: Path) -> Path:
    folder = tmp_path / "edited"
    shutil.copytree(session, folder)
    return folder


def _units_contradict(folder: Path) -> str:
    toml = folder / "session.toml"
    toml.write_text(toml.read_text().replace('kind = "wrench"', 'kind = "wrench"\nunits = "kN"'))
    return "channel 'Force_X' is in N as the file states, but force.units says kN"


def _another_plate(folder: Path) -> str:
    export = folder / PLATE_FILE
    export.write_bytes(export.read_bytes().replace(b"Force-plate 1", b"Force-plate 2", 1))
    return "no force plate named 'Force-plate 2' (the plate of indentation_f_1.tsv) in its " \
           "parameters; it has: Force-plate 1"


@pytest.mark.parametrize("spoil", [_units_contradict, _another_plate])
def test_a_plate_qtm_contradicts_is_refused_before_a_frame(plate_session, tmp_path,
                                                           spoil) -> None:
    session = _copy(plate_session, tmp_path)
    words = spoil(session)
    with replaying(plate_session) as server:
        res = CliRunner().invoke(cli, ["live", str(session), "--qtm",
                                       f"127.0.0.1:{server.port}", "--out",
                                       str(tmp_path / "out"), "--timeout", "10"])
    assert res.exit_code == 2 and words in res.stderr, res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and not (tmp_path / "out").exists()


def test_a_plate_session_against_a_capture_without_plates_is_refused(plate_session, twin_session,
                                                                     tmp_path) -> None:
    """QTM streams the analog board's capture (no plate): the plate's force is not there."""
    with replaying(twin_session) as server:
        res = CliRunner().invoke(cli, ["live", str(plate_session), "--qtm",
                                       f"127.0.0.1:{server.port}", "--out",
                                       str(tmp_path / "out"), "--timeout", "10"])
    assert res.exit_code == 2 and "no force plate in its parameters" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and not (tmp_path / "out").exists()


def test_the_plate_is_picked_by_the_exports_name(plate_session) -> None:
    """Of QTM's plates the export's (FORCE_PLATE_NAME); its units checked as ingest checks
    the export's; a plate whose force is in kN is converted, one in V refused."""
    cfg = read_session(plate_session)
    labels = cfg.mocap.phantom_markers + cfg.mocap.indenter_markers
    nine = ["Force_X", "Force_Y", "Force_Z", "Moment_X", "Moment_Y", "Moment_Z", "COP_X",
            "COP_Y", "COP_Z"]

    def plate(pid: int, name: str, force: str = "N") -> ForcePlate:
        return ForcePlate(pid, name, 1000.0, nine, [force] * 3 + [f"{force}*m"] * 3 + ["mm"] * 3)

    other, mine = plate(1, "Force-plate 2"), plate(2, "Force-plate 1")
    layout = live_layout(QtmParameters(SOURCE, 500.0, labels, [], [other, mine]), cfg)
    assert layout.device == mine
    kn = live_layout(QtmParameters(SOURCE, 500.0, labels, [], [plate(2, "Force-plate 1",
                                                                     "kN")]), cfg)
    got = to_force(kn, np.ones((2, 9)), cfg)
    np.testing.assert_array_equal(got.values, np.full((2, 6), 1000.0))
    with pytest.raises(BadInput, match="Force_X. is in V, which does not fit force.kind"):
        live_layout(QtmParameters(SOURCE, 500.0, labels, [], [plate(2, "Force-plate 1",
                                                                    "V")]), cfg)

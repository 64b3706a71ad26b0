"""A twin session taken through the offline stages, for the tests of one force route."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
from click.testing import CliRunner

from pipeline.cli import cli
from sync.sync_accuracy import TARGETS, sync_errors


def staged_twin(folder: Path, *synth_options: str) -> Path:
    """``pipeline synth`` with ``synth_options`` (seed 3, 2 locations x 2 repeats), then
    ingest, sync and extract, into ``folder`` (s/, s.mcap, synced.h5, states.h5)."""
    for args in (("synth", folder / "s", "--seed", "3", "--locations", "2", "--repeats", "2",
                  *synth_options, "--no-rrd"),
                 ("ingest", folder / "s", "--out", folder / "s.mcap", "--no-rrd"),
                 ("sync", folder / "s.mcap", "--out", folder / "synced.h5", "--no-rrd"),
                 ("extract", folder / "synced.h5", "--out", folder / "states.h5", "--no-rrd")):
        res = CliRunner().invoke(cli, ["-q", *map(str, args)])
        assert res.exit_code == 0, res.output + res.stderr
    return folder


def shared_clock_checked(folder: Path) -> dict:
    """The staged twin's sync against its truth, checked for a force on the mocap's clock:
    the policy "shared", no offset or drift estimated, tip, force and presses within the sync
    targets; the synced file's clock record, for a route's own checks."""
    err = sync_errors(folder / "synced.h5", folder / "s" / "truth.h5")
    with h5py.File(folder / "synced.h5") as s:
        clock = json.loads(s.attrs["calibration"])["clock"]
    assert clock["policy"] == "shared"
    assert err["clock_offset_ms"] == 0 and err["clock_drift_ppm"] == 0
    for key in ("tip_rms_mm", "tip_offset_mm", "force_rms_n"):
        assert err[key] <= TARGETS[key], (key, err)
    assert err["presses"] == 4 and err["presses_missed"] == err["presses_extra"] == 0
    assert err["locations_mixed"] == 0
    return clock

"""`pipeline sync` on phantom-twin sessions against their truth: sync's accuracy targets
over 5 seeds, presses and locations, gap flags, and the recording.

Each session is small in presses (2 locations x 1 repeat) but long in time (press cycles of
about a minute): the trigger's time stamps are rounded to 1 ms on both sides, so the drift can
only be pinned to a few ppm over a couple of minutes of pulses.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from core.recording import rrd_entities, rrd_timelines
from ingest.ingest_stage import run_ingest
from pipeline.cli import cli
from sim.twin.synth_params import SynthParams
from sim.twin.synth_stage import run_synth
from sync.gaps import FILLED, MISSING
from sync.sync_accuracy import TARGETS, match_presses, sync_errors
from sync.sync_params import SyncParams
from sync.sync_stage import run_sync

SEEDS = (0, 1, 2, 3, 4)


@pytest.fixture(scope="module")
def sessions(tmp_path_factory: pytest.TempPathFactory) -> dict[int, tuple[Path, Path, Path]]:
    """seed -> (session folder, ingested MCAP, synced HDF5); seed 0 synced through the CLI."""
    root = tmp_path_factory.mktemp("twin")
    out = {}
    for seed in SEEDS:
        folder = run_synth(None, root / f"s{seed}", SynthParams(
            seed=seed, locations=2, repeats=1, press_seconds=60.0, pivot_seconds=10.0))
        mcap = root / f"s{seed}.mcap"
        run_ingest(folder, mcap)
        synced = root / f"s{seed}.h5"
        if seed == 0:
            res = CliRunner().invoke(cli, ["-q", "sync", str(mcap), "--out", str(synced)])
            assert res.exit_code == 0, res.output
        else:
            run_sync(mcap, synced)
        out[seed] = (folder, mcap, synced)
    return out


@pytest.mark.parametrize("seed", SEEDS)
def test_accuracy_targets_against_truth(sessions: dict, seed: int) -> None:
    folder, _, synced = sessions[seed]
    err = sync_errors(synced, folder / "truth.h5")
    for key, limit in TARGETS.items():
        assert err[key] <= limit, f"seed {seed}: {key} = {err[key]:.4f} > {limit}"
    # the reported uncertainty covers the clock error
    assert err["clock_offset_ms"] <= 4 * err["clock_offset_sd_ms"] + 0.05
    assert err["clock_drift_ppm"] <= 4 * err["clock_drift_sd_ppm"] + 0.5
    assert err["presses"] == 2 and err["presses_missed"] == 0 and err["locations_mixed"] == 0
    assert err["presses_extra"] == 0 and err["presses_merged"] == 0
    assert err["tip_coverage"] >= 0.95
    assert err["force_rms_loaded_n"] <= TARGETS["force_rms_n"]


def test_presses_locations_and_repeats(sessions: dict) -> None:
    folder, _, synced = sessions[0]
    with h5py.File(synced) as s, h5py.File(folder / "truth.h5") as t:
        assert s["calibration"].attrs["clock_method"] == "trigger"
        rate = t.attrs["rate_hz"]
        for k, name in enumerate(sorted(s["presses"])):
            g = s["presses"][name]
            assert g.attrs["location"] == t["presses/location"][k]
            assert g.attrs["repeat"] == t["presses/repeat"][k]
            frames = np.round(g["time_ns"][:] * 1e-9 * rate).astype(int)
            on, off = frames[g.attrs["onset_index"]], frames[g.attrs["release_index"] - 1]
            # contact onset and release where the force crosses the contact level (0.05 N):
            # inside the true contact, and the true force there is still small
            assert t["presses/start_frame"][k] <= on < off <= t["presses/end_frame"][k]
            true_force = t["force/magnitude"]
            assert true_force[on] < 0.1 and true_force[off] < 0.1
            assert true_force[on - 1] < 0.06 and true_force[off + 1] < 0.06
            assert g["force_magnitude"][0] < 0.05 and g.attrs["onset_index"] > 0
            peak = g["force_magnitude"][g.attrs["peak_index"]]
            assert abs(peak - t["presses/fmax"][k]) < 0.2      # planned peak + tremor


def test_gap_flags_follow_what_the_cameras_missed(sessions: dict) -> None:
    folder, _, synced = sessions[1]
    with h5py.File(synced) as s, h5py.File(folder / "truth.h5") as t:
        visible = t["mocap/visible"][:, :25]
        rate = t.attrs["rate_hz"]
        n_filled = n_missing = 0
        for name in s["presses"]:
            g = s["presses"][name]
            idx = np.round(g["time_ns"][:] * 1e-9 * rate).astype(int)
            q = g["quality"][:, :25]
            seen = visible[idx]
            assert (q[seen] == 0).all()
            assert ((q[~seen] & (FILLED | MISSING)) > 0).all()
            pts = g["points"][:, :25]
            assert np.isnan(pts[(q & MISSING) > 0]).all()
            assert np.isfinite(pts[(q & FILLED) > 0]).all()
            n_filled += int(((q & FILLED) > 0).sum())
            n_missing += int(((q & MISSING) > 0).sum())
        assert n_filled > 0


def test_data_driven_clock_on_the_twin(sessions: dict) -> None:
    """Two presses of about a minute each: slow force changes pin the lag to about a
    millisecond only (the reported uncertainty says so), and matter as little to the force.
    The contact-state seed is a few tenths of a second off on presses this slow: the per-press
    scan must walk to the lag from there."""
    folder, mcap, _ = sessions[0]
    out = mcap.with_name("data.h5")
    run_sync(mcap, out, SyncParams(clock="data"))
    err = sync_errors(out, folder / "truth.h5")
    with h5py.File(out) as s:
        assert s["calibration"].attrs["clock_method"] == "data"
    assert err["clock_offset_ms"] <= 2.0
    assert err["clock_offset_ms"] <= 4 * err["clock_offset_sd_ms"]
    assert err["force_rms_n"] <= TARGETS["force_rms_n"]


def test_press_matching_is_one_to_one() -> None:
    """True presses at frames 0-99, 200-299, 400-499, 600-699 (locations 0, 1, 0, 1)."""
    start, end = np.array([0, 200, 400, 600]), np.array([99, 299, 499, 699])
    truth_loc = np.array([0, 1, 0, 1])
    exact = match_presses([(10, 90), (210, 290), (410, 490), (610, 690)], [0, 1, 0, 1],
                          start, end, truth_loc)
    assert exact == {"presses_missed": 0, "presses_extra": 0, "presses_merged": 0,
                     "locations_mixed": 0}
    # the first two merged into one, an extra press where there was none, the last split
    found = match_presses([(10, 250), (410, 490), (550, 580), (610, 640), (650, 690)],
                          [0, 0, 2, 1, 1], start, end, truth_loc)
    assert found == {"presses_missed": 1, "presses_extra": 2, "presses_merged": 1,
                     "locations_mixed": 0}


def test_recording_shows_alignment_tip_and_gaps(sessions: dict) -> None:
    _, _, synced = sessions[0]
    ents = rrd_entities(synced.with_suffix(".rrd"))
    for e in ("/force/before", "/force/after", "/depth/tip", "/quality/filled",
              "/quality/missing", "/quality/saturated", "/quality/over_range"):
        assert "Scalars" in ents[e] and "SeriesLines" in ents[e], e    # named, coloured
    assert "EncodedImage" in ents["/force_vs_depth"]          # a plot with axes
    for e in ("/scene/tip", "/scene/phantom", "/scene/cluster"):
        assert "Points3D" in ents[e], e
    for e in ("/scene/surface", "/scene/shaft", "/scene/tip_path"):
        assert "LineStrips3D" in ents[e], e
    assert "TextLog" in ents["/presses"] and "ViewCoordinates" in ents["/"]
    assert rrd_timelines(synced.with_suffix(".rrd")) == {"mocap_time"}

"""`pipeline sync` on a small analytic session written straight to MCAP: output layout,
recording, both clock paths, and every bad input (exit 2, one line, nothing written)."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner
from helpers.raw_sessions import DRIFT, LOG_RATE, OFFSET, RATE, analytic_session

from core.errors import BadInput
from core.recording import rrd_entities, rrd_has_blueprint
from core.series import RawSession
from data_schema.hdf5 import validate_h5
from data_schema.synced import SYNCED
from ingest.ingest_params import IngestParams
from ingest.mcap_io import write_raw_mcap
from pipeline.cli import cli
from sync.gaps import MISSING
from sync.sync import sync_session
from sync.sync_params import SyncParams
from sync.synced_file import write_synced


def _mcap(tmp_path: Path, session: RawSession, name: str = "s.mcap") -> Path:
    path = tmp_path / name
    write_raw_mcap(path, session, {}, IngestParams().compression)
    return path


def _sync(mcap: Path, out: Path, *extra: str):
    return CliRunner().invoke(cli, ["-q", "sync", str(mcap), "--out", str(out), *extra])


@pytest.mark.filterwarnings("error")
def test_sync_writes_valid_presses_and_recording(tmp_path: Path) -> None:
    mcap = _mcap(tmp_path, analytic_session())
    out = tmp_path / "s.h5"
    res = _sync(mcap, out)
    assert res.exit_code == 0, res.output
    validate_h5(out, SYNCED)
    with h5py.File(out) as h:
        assert len(h["presses"]) == 4
        assert [h[f"presses/{k:03d}"].attrs["location"] for k in range(4)] == [0, 1, 0, 1]
        assert [h[f"presses/{k:03d}"].attrs["repeat"] for k in range(4)] == [0, 0, 1, 1]
        cal = h["calibration"].attrs
        assert cal["clock_method"] == "trigger"
        assert abs(cal["clock_offset_s"] - OFFSET) < 0.5e-3
        assert abs(cal["clock_drift_ppm"] - DRIFT) < 4 * cal["clock_drift_sd_ppm"] + 5
        g = h["presses/001"]
        i = g.attrs["peak_index"]
        # depth 6 mm at peak = 7 N; the bias (0.1, -0.2, 0.3) N is tared away
        assert abs(g["force_magnitude"][i] - 7.0) < 0.1
        assert abs(g["depth"][i] - 0.006) < 0.5e-3
        assert g["force_magnitude"][0] < 0.05                  # unloaded margin kept
        assert h["presses"].attrs["cut_off"] == 0
        # the rest next to the press is what was left of the bias after the start tare: ~0
        assert np.abs(g.attrs["rest_force_n"]).max() < 0.01
        assert list(h["point_names"].asstr()[-2:]) == ["P24", "tip"]
        prov = json.loads(h.attrs["provenance"])
        assert prov["stage"] == "sync" and str(mcap) in prov["inputs"]
    rrd = tmp_path / "s.rrd"
    ents = rrd_entities(rrd)
    for e in ("/force/before", "/force/after", "/depth/tip", "/force_vs_depth",
              "/scene/tip", "/scene/cluster", "/scene/phantom", "/scene/surface",
              "/quality/filled", "/presses"):
        assert e in ents, e
    assert "Points3D" in ents["/scene/tip"] and "EncodedImage" in ents["/force_vs_depth"]
    assert rrd_has_blueprint(rrd)


def test_marker_missing_through_a_press_is_not_invented(tmp_path: Path) -> None:
    raw = analytic_session()
    t = raw.markers.time_ns * 1e-9
    raw.markers.positions[(t > 1.0) & (t < t[-1] - 1.0), 12] = np.nan
    r = sync_session(raw, SyncParams())
    for rec in r.presses:
        inside = slice(rec.press.onset, rec.press.release)
        assert np.isnan(rec.points[inside, 12]).all()
        assert (rec.quality[inside, 12] == MISSING).all()
    write_synced(tmp_path / "m.h5", r, {}, "m.mcap")
    with h5py.File(tmp_path / "m.h5") as h:
        for g in h["presses"].values():
            assert 12 in g.attrs["points_missing_throughout"]


def test_data_clock_agrees_with_trigger(tmp_path: Path) -> None:
    mcap = _mcap(tmp_path, analytic_session(seed=1))
    fits = {}
    for method in ("trigger", "data"):
        out = tmp_path / f"{method}.h5"
        res = _sync(mcap, out, "--clock", method, "--no-rrd")
        assert res.exit_code == 0, res.output
        with h5py.File(out) as h:
            fits[method] = dict(h["calibration"].attrs)
        assert not (tmp_path / f"{method}.rrd").exists()
    assert fits["data"]["clock_method"] == "data"
    assert abs(fits["data"]["clock_offset_s"] - OFFSET) < 1e-3
    assert abs(fits["trigger"]["clock_offset_s"] - OFFSET) < 0.5e-3


def _bad(tmp_path: Path, session: RawSession, pattern: str, *extra: str) -> None:
    tmp_path.mkdir(exist_ok=True)
    mcap = _mcap(tmp_path, session)
    before = mcap.read_bytes()
    out = tmp_path / "bad.h5"
    res = _sync(mcap, out, *extra)
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), res.output
    assert pattern in lines[0], lines[0]
    assert not out.exists() and not (tmp_path / "bad.rrd").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.mcap"]
    assert mcap.read_bytes() == before


def test_cluster_hidden_through_a_press(tmp_path: Path) -> None:
    s = analytic_session()
    t = s.markers.time_ns * 1e-9
    hide = (t > 5.0) & (t < 8.0)                          # the whole second press
    s.markers.positions[np.ix_(hide, [25, 26])] = np.nan
    _bad(tmp_path, s, "trial.tsv:frames")


def test_no_unloaded_start_to_tare(tmp_path: Path) -> None:
    s = analytic_session()
    f = s.force
    start = np.searchsorted(f.time_ns, int((OFFSET + 2.5) * 1e9))   # at the first peak
    f.time_ns, f.values, f.trigger = f.time_ns[start:], f.values[start:], f.trigger[start:]
    _bad(tmp_path, s, "force.csv:sample 0: ")


def test_log_starting_under_a_steady_load(tmp_path: Path) -> None:
    """A held press at the start looks flat, but then the force between presses is not 0."""
    s = analytic_session()
    s.force.values[: int(1.2 * LOG_RATE), 2] += 5.0
    _bad(tmp_path, s, "force.csv:sample 0: force log did not start unloaded")


def test_a_logger_an_hour_ahead_is_found_and_a_bounded_search_refuses_it() -> None:
    """Independent clocks: a logger stamped an hour later still overlaps the mocap at the
    right lag, which the unbounded search finds; a search bounded to 30 s cannot."""
    s = analytic_session()
    s.force.time_ns = s.force.time_ns + 3_600_000_000_000
    s.trigger_event = None
    with pytest.raises(BadInput, match="do not overlap in time for any clock offset within"):
        sync_session(s, SyncParams(clock="data", max_offset_s=30.0))
    fit = sync_session(s, SyncParams(clock="data")).clock
    assert abs(fit.offset_s - (3600 + OFFSET)) < 4 * fit.offset_sd_s + 1e-4


def test_pivot_without_rotation(tmp_path: Path) -> None:
    s = analytic_session()
    p = s.pivot.positions
    s.pivot.positions = np.repeat(p[:1], len(p), axis=0) + np.random.default_rng(0).normal(
        0, 1e-4, p.shape)
    _bad(tmp_path, s, "pivot.tsv: pivot recording has too little rotation")


def test_trigger_asked_for_but_not_recorded(tmp_path: Path) -> None:
    _bad(tmp_path, analytic_session(trigger=False), "no trigger channel", "--clock", "trigger")


def test_output_never_overwrites_the_input(tmp_path: Path) -> None:
    mcap = _mcap(tmp_path, analytic_session(presses=2))
    before = mcap.read_bytes()
    res = _sync(mcap, mcap)
    assert res.exit_code == 2 and "overwrite" in res.output
    assert mcap.read_bytes() == before


@pytest.mark.parametrize("bad", ["--max-gap-ms=x", "--clock=gps", "--margin-s=-1",
                                 "--max-gap-ms=-5", "--location-radius-mm=-1",
                                 "--location-radius-mm=0"])
def test_bad_options_are_usage_errors(tmp_path: Path, bad: str) -> None:
    mcap = _mcap(tmp_path, analytic_session(presses=2))
    out = tmp_path / "o.h5"
    res = _sync(mcap, out, bad)
    assert res.exit_code == 2, res.output
    assert bad.split("=")[0] in res.output and "Traceback" not in res.output
    assert not out.exists()


@pytest.mark.parametrize("field", ["margin_s", "max_gap_s", "location_radius_m"])
def test_bad_parameters_are_bad_input_for_library_callers(field: str) -> None:
    with pytest.raises(BadInput, match=field):
        sync_session(analytic_session(presses=1), SyncParams(**{field: -1.0}))


def test_swapped_indenter_labels_are_refused(tmp_path: Path) -> None:
    """Labels of two indenter markers swapped in the trial but not in the pivot recording:
    every rigid fit is poor, so there is no tip anywhere."""
    s = analytic_session()
    s.markers.positions[:, [26, 27]] = s.markers.positions[:, [27, 26]]
    _bad(tmp_path, s, "trial.tsv: the indenter has a usable pose in only 0 of")


def test_poor_fits_through_one_press_are_refused(tmp_path: Path) -> None:
    s = analytic_session()
    t = s.markers.time_ns * 1e-9
    during = (t > 5.0) & (t < 8.0)                        # the whole second press
    pos = s.markers.positions
    pos[np.ix_(during, [26, 27])] = pos[np.ix_(during, [27, 26])]
    _bad(tmp_path, s, "press 1: every indenter fit through the whole press is poor")


@pytest.mark.parametrize("load", [0.3, 0.45])
def test_log_starting_under_a_small_steady_load(tmp_path: Path, load: float) -> None:
    """Below the detection level, but well above the noise: presses would merge."""
    s = analytic_session()
    s.force.values[: int(1.2 * LOG_RATE), 2] += load
    _bad(tmp_path, s, f"force between presses is {load:.2f} N")


def test_bias_creep_is_re_tared_at_every_press(tmp_path: Path) -> None:
    """A bias creeping 0.6 mN/s on Fz (ten times the twin's sensor): 40 mN by the end of a
    16-press session, twice the force target. Each press is re-tared from the rest next to
    it, and the rest that was removed is stored."""
    n = 16
    s = analytic_session(presses=n)
    t_f = s.force.time_ns * 1e-9
    creep = np.array([0.3, -0.2, 0.6, 0.01, -0.02, 0.0]) * 1e-3
    s.force.values += np.outer(t_f, creep)
    mcap = _mcap(tmp_path, s)
    out = tmp_path / "s.h5"
    res = _sync(mcap, out, "--no-rrd")
    assert res.exit_code == 0, res.output
    with h5py.File(out) as h:
        assert len(h["presses"]) == n
        for k in range(n):
            g = h[f"presses/{k:03d}"]
            on, peak = g.attrs["onset_index"], g.attrs["peak_index"]
            assert abs(g["force_magnitude"][peak] - 7.0) < 0.03, k
            margin = g["force"][: on - 25]                           # unloaded
            assert np.linalg.norm(margin.mean(axis=0)) < 3e-3, k
        for g in h["presses"].values():
            t_on, t_off = (OFFSET + (1 + DRIFT * 1e-6) * g.attrs[key] * 1e-9
                           for key in ("onset_ns", "release_ns"))
            want = np.outer([t_on, t_off], creep[:3]) - creep[:3] * 1.0   # tare ~ t = 1 s
            np.testing.assert_allclose(g.attrs["rest_force_n"], want, atol=3e-3)


def test_presses_cut_off_by_either_recording_are_left_out(tmp_path: Path) -> None:
    s = analytic_session()
    start = int(2.5e9)                                     # mocap starts inside press 0
    keep = s.markers.time_ns >= start
    s.markers.time_ns = s.markers.time_ns[keep] - start
    s.markers.positions = s.markers.positions[keep]
    s.markers.events = [(lab, t - start) for lab, t in s.markers.events if t >= start]
    f = s.force
    end = np.searchsorted(f.time_ns, int((OFFSET + 14.5) * 1e9))    # log ends inside press 3
    f.time_ns, f.values, f.trigger = f.time_ns[:end], f.values[:end], f.trigger[:end]
    mcap = _mcap(tmp_path, s)
    out = tmp_path / "s.h5"
    res = _sync(mcap, out, "--no-rrd")
    assert res.exit_code == 0, res.output
    assert "2 cut off" in res.output
    with h5py.File(out) as h:
        assert h["presses"].attrs["cut_off"] == 2 and len(h["presses"]) == 2
        for g in h["presses"].values():
            on = g.attrs["onset_index"]
            assert on >= 0.4 * RATE and g["force_magnitude"][0] < 0.05
            assert abs(g["force_magnitude"][g.attrs["peak_index"]] - 7.0) < 0.1


def test_dead_trigger_channel_falls_back_to_the_data_clock(tmp_path: Path) -> None:
    s = analytic_session(seed=1)
    ttl = np.zeros_like(s.force.trigger)
    ttl[3000:3010] = 5.0                                    # one pulse, then nothing
    s.force.trigger = ttl
    mcap = _mcap(tmp_path, s)
    out = tmp_path / "s.h5"
    res = _sync(mcap, out, "--no-rrd")
    assert res.exit_code == 0, res.output
    with h5py.File(out) as h:
        assert h["calibration"].attrs["clock_method"] == "data"
        assert abs(h["calibration"].attrs["clock_offset_s"] - OFFSET) < 1e-3
        assert "1 pulse edges" in json.loads(h.attrs["calibration"])["clock"]["note"]
    _bad(tmp_path / "strict", s, "trigger: 1 pulse edges", "--clock", "trigger")

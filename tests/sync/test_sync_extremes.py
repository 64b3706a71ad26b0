"""Sync and extract at the extremes: no silent wrong data.

A twin session without a trigger whose logger clock is 36 s off (beyond a +-30 s search
window), then the same session altered in its raw MCAP: the logger's clock moved further
(-45 s) or stamped from its boot or the epoch (+3600 s, +1.7e9 s), the force log cut to one
press, the force of another session, gauge voltages amplified onto the .cal's +-10 V rail,
quantised coarser than their noise (a flat peak that is no clip), one press pushed beyond
the sensor's rated load, a periodic trigger that the data must disambiguate. Each ends as a
result checked against the twin's truth or as a one-line refusal (exit 2, no file). And
extract's --step bounds.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from calib.force_tare import noise_sigma
from core.errors import BadInput
from core.series import RawSession
from ingest.ingest_params import IngestParams
from ingest.mcap_io import read_raw_mcap, write_raw_mcap
from pipeline.cli import cli
from sim.twin.synth_params import SynthParams
from sim.twin.synth_stage import run_synth
from sync.force_conditioning import FLAT_RUN, on_rail
from sync.sync import sync_session
from sync.sync_params import SyncParams

OFFSET_S = 36.0
COMPRESSION = IngestParams().compression      # ingest's default
TWIN = {"locations": 2, "repeats": 4, "trigger": False, "pivot_seconds": 5.0}
PRESSES = 8


def _cli(*args: object):
    return CliRunner().invoke(cli, ["-q", *map(str, args)])


@pytest.fixture(scope="module")
def twin(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """Seed 7, logger 36 s off, no trigger: its folder, raw session, MCAP and synced file; and
    the raw session of another seed (its force is not this session's)."""
    root = tmp_path_factory.mktemp("stability_sync")
    folder = run_synth(None, root / "s", SynthParams(seed=7, offset_s=OFFSET_S, **TWIN))
    run_synth(None, root / "o", SynthParams(seed=8, **TWIN))
    for name in ("s", "o"):
        res = _cli("ingest", root / name, "--out", root / f"{name}.mcap", "--no-rrd")
        assert res.exit_code == 0, res.output
    res = _cli("sync", root / "s.mcap", "--out", root / "s.h5", "--no-rrd")
    with h5py.File(folder / "truth.h5") as t:
        truth = {"offset_s": float(t["clock/offset_s"][()]), "rate_hz": float(t.attrs["rate_hz"]),
                 "start": t["presses/start_frame"][()], "end": t["presses/end_frame"][()],
                 "drift_ppm": float(t["clock/drift_ppm"][()])}
    return {"root": root, "folder": folder, "raw": read_raw_mcap(root / "s.mcap"),
            "other": read_raw_mcap(root / "o.mcap"), "synced": root / "s.h5",
            "sync_output": res, "truth": truth}


def _sync_variant(twin: dict, tmp_path: Path, raw: RawSession, *extra: str):
    """Write ``raw`` as an MCAP under ``tmp_path`` and sync it through the CLI."""
    mcap = tmp_path / "v.mcap"
    write_raw_mcap(mcap, raw, {}, COMPRESSION)
    out = tmp_path / "v.h5"
    return _cli("sync", mcap, "--out", out, "--no-rrd", *extra), out


def _refused(res, out: Path, *words: str) -> None:
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), res.output
    assert "force.csv: clock: " in lines[0], lines[0]
    for w in words:
        assert w in lines[0], lines[0]
    assert not out.exists()


def _clock(out: Path) -> tuple[float, float]:
    with h5py.File(out) as s:
        a = s["calibration"].attrs
        assert a["clock_method"] == "data"
        return float(a["clock_offset_s"]), float(a["clock_offset_sd_s"])


def test_an_offset_beyond_30_s_is_found(twin: dict) -> None:
    """36 s: a search bounded at +-30 s would lock a press cycle away (here 30.2 s) and exit
    0; the whole overlap is searched."""
    assert twin["sync_output"].exit_code == 0, twin["sync_output"].output
    offset, sd = _clock(twin["synced"])
    err = abs(offset - twin["truth"]["offset_s"])
    assert err <= 0.5e-3 and err <= 4 * sd + 0.05e-3, (offset, twin["truth"]["offset_s"], sd)


def test_a_negative_offset_of_45_s_is_found(twin: dict, tmp_path: Path) -> None:
    """The logger's stamps moved 81 s earlier: the true offset becomes -45 s (the session is
    longer than that)."""
    raw = copy.deepcopy(twin["raw"])
    assert raw.markers.time_ns[-1] * 1e-9 > 45.0
    raw.force.time_ns = raw.force.time_ns - 81_000_000_000
    res, out = _sync_variant(twin, tmp_path, raw)
    assert res.exit_code == 0, res.output
    offset, _ = _clock(out)
    assert abs(offset - (twin["truth"]["offset_s"] - 81.0)) <= 0.5e-3


@pytest.mark.parametrize("shift_s", [3600, 1_700_000_000])
def test_a_logger_stamped_from_boot_or_the_epoch_is_found(twin: dict, tmp_path: Path,
                                                         shift_s: int) -> None:
    """Logger stamps an hour (from its boot) or 1.7e9 s (the epoch) ahead of the mocap's:
    a search bounded by the longer recording's length (a few minutes) would never reach
    them."""
    raw = copy.deepcopy(twin["raw"])
    raw.force.time_ns = raw.force.time_ns + shift_s * 1_000_000_000
    res, out = _sync_variant(twin, tmp_path, raw)
    assert res.exit_code == 0, res.output
    offset, sd = _clock(out)
    err = abs(offset - (twin["truth"]["offset_s"] + shift_s))
    assert err <= 0.5e-3 and err <= 4 * sd + 0.05e-3, (offset, shift_s, sd)


def _window(raw: RawSession, truth: dict, first: int, last: int) -> RawSession:
    """The force log cut to the rest before press ``first`` .. the rest after press ``last``."""
    t = truth
    to_logger = lambda frame: t["offset_s"] + (1 + t["drift_ppm"] * 1e-6) * frame / t["rate_hz"]  # noqa: E731
    a = to_logger(0.3 * t["end"][first - 1] + 0.7 * t["start"][first])
    b = to_logger(0.5 * t["end"][last] + 0.5 * t["start"][last + 1])
    out = copy.deepcopy(raw)
    f = out.force
    keep = (f.time_ns * 1e-9 >= a) & (f.time_ns * 1e-9 < b)
    f.time_ns, f.values = f.time_ns[keep], f.values[keep]
    return out


def test_a_force_log_of_one_press_is_refused(twin: dict, tmp_path: Path) -> None:
    """One press matches any of the session's presses of a similar shape."""
    raw = _window(twin["raw"], twin["truth"], 2, 2)
    res, out = _sync_variant(twin, tmp_path, raw)
    _refused(res, out, "rests on 1 press")


def test_force_of_another_session_is_refused(twin: dict, tmp_path: Path) -> None:
    raw = copy.deepcopy(twin["raw"])
    raw.force = copy.deepcopy(twin["other"].force)
    res, out = _sync_variant(twin, tmp_path, raw)
    _refused(res, out, "cannot be locked")


def _near_clock(twin: dict) -> tuple[RawSession, dict]:
    """The raw session with the logger's stamps moved back by 36 s (its offset within +-30 s,
    so that a force check fails on its own), and its truth."""
    raw = copy.deepcopy(twin["raw"])
    raw.force.time_ns = raw.force.time_ns - int(OFFSET_S * 1e9)
    return raw, {**twin["truth"], "offset_s": twin["truth"]["offset_s"] - OFFSET_S}


def _rail_presses(volts: np.ndarray, raw: RawSession, truth: dict, rail: float) -> set[int]:
    """The true presses (index in time order) during which a gauge leaves +-``rail`` V."""
    beyond = raw.force.time_ns[(np.abs(volts) >= rail).any(axis=1)] * 1e-9
    frames = (beyond - truth["offset_s"]) / (1 + truth["drift_ppm"] * 1e-6) * truth["rate_hz"]
    return {k for k, (a, b) in enumerate(zip(truth["start"], truth["end"], strict=True))
            if ((frames >= a) & (frames <= b)).any()}


def _states_presses(states: Path) -> set[int]:
    with h5py.File(states) as s:
        return set(s["states/sequence"][()].tolist())


@pytest.mark.parametrize("rail", [10.0, 7.5])
def test_clipped_gauges_flag_their_presses_and_extract_leaves_them_out(
        twin: dict, tmp_path: Path, rail: float) -> None:
    """Gauges amplified so that the strongest presses reach the .cal's +-10 V rail (matrix
    scaled back: the force is the same), or an amplifier's +-7.5 V that the .cal does not
    know (a flat top): the clipped presses are flagged, left out, counted."""
    raw, truth = _near_clock(twin)
    gain = rail / (0.93 * np.abs(raw.force.values).max())
    volts = raw.force.values * gain
    clipped = _rail_presses(volts, raw, truth, rail)
    assert 0 < len(clipped) < PRESSES
    raw.force.values = np.clip(volts, -rail, rail)
    raw.calibration.matrix = raw.calibration.matrix / gain
    res, out = _sync_variant(twin, tmp_path, raw)
    assert res.exit_code == 0, res.output
    assert f"{len(clipped)} press{'es' if len(clipped) > 1 else ''} with a gauge on the " \
           "amplifier's rail" in res.output, res.output
    with h5py.File(out) as s:
        bits = json.loads(s.attrs["force_bits"])
        flagged = {k for k, g in enumerate(s["presses"].values())
                   if (g["force_quality"][()] & bits["saturated"]).any()}
    assert flagged == clipped
    states = tmp_path / "states.h5"
    res = _cli("extract", out, "--out", states, "--no-rrd")
    assert res.exit_code == 0, res.output
    assert f"left out: {len(clipped)} press{'es' if len(clipped) > 1 else ''} " \
           "saturated/over-range" in res.output
    assert _states_presses(states) == set(range(PRESSES)) - clipped


def test_an_over_range_press_is_left_out(twin: dict, tmp_path: Path) -> None:
    """Press 3's load scaled to 20 N (a Nano17's rated Fz is 17 N)."""
    raw, t = _near_clock(twin)
    f = raw.force
    frames = ((f.time_ns * 1e-9 - t["offset_s"]) / (1 + t["drift_ppm"] * 1e-6) * t["rate_hz"])
    inside = (frames >= t["start"][3] - 50) & (frames <= t["end"][3] + 50)
    rest = f.values[inside][:20].mean(axis=0)
    wrench = (f.values[inside] - rest) @ raw.calibration.matrix.T
    scale = 20.0 / np.linalg.norm(wrench[:, :3], axis=1).max()
    f.values[inside] = rest + (f.values[inside] - rest) * scale
    res, out = _sync_variant(twin, tmp_path, raw)
    assert res.exit_code == 0, res.output
    assert "1 press with a force beyond the sensor's rated load" in res.output, res.output
    states = tmp_path / "states.h5"
    res = _cli("extract", out, "--out", states, "--no-rrd")
    assert res.exit_code == 0, res.output
    assert "left out: 1 press saturated/over-range" in res.output, res.output
    assert _states_presses(states) == set(range(PRESSES)) - {3}
    with h5py.File(states) as s:
        assert s["states/force"][()].max() < 17.0
        assert json.loads(s.attrs["excluded"])["saturated_or_over_range"] > 0


@pytest.mark.parametrize(("step", "words"), [
    ("nan", "not a finite number"), ("inf", "not a finite number"), ("0", "must be > 0"),
    ("-1", "must be > 0"), ("1e-9", "below the force noise floor"),
    ("1e-3", "below the force noise floor"), ("100", "above the largest peak force")])
def test_step_out_of_bounds_is_one_line(twin: dict, tmp_path: Path, step: str,
                                        words: str) -> None:
    out = tmp_path / "st.h5"
    res = _cli("extract", twin["synced"], "--out", out, "--no-rrd", f"--step={step}")
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: --step "), res.output
    assert words in lines[0] and not out.exists()


def test_step_floor_is_three_noise_widths(twin: dict, tmp_path: Path) -> None:
    """Just above 3 x the noise sync measured: accepted; just below: refused."""
    with h5py.File(twin["synced"]) as s:
        noise = json.loads(s.attrs["calibration"])["force"]["noise_force_n"]
    floor = max(3 * noise, 1 / 320)
    ok = _cli("extract", twin["synced"], "--out", tmp_path / "a.h5", "--no-rrd",
              f"--step={floor * 1.05}")
    assert ok.exit_code == 0, ok.output
    bad = _cli("extract", twin["synced"], "--out", tmp_path / "b.h5", "--no-rrd",
               f"--step={floor * 0.95}")
    assert bad.exit_code == 2 and "noise floor" in bad.output


def _quantised(volts: np.ndarray, steps_per_noise: float) -> np.ndarray:
    """Gauge voltages rounded to a converter step ``steps_per_noise`` times each channel's
    noise width (a quiet DAQ, or a CSV written with few decimals)."""
    step = noise_sigma(volts) * steps_per_noise
    return np.round(volts / step) * step


def _flat_extremes(volts: np.ndarray) -> int:
    """Samples in runs of :data:`FLAT_RUN` identical values at a channel's extreme: what a
    flat-top rule that did not ask for noise wider than the step would call a clip."""
    out = 0
    for c in volts.T:
        for extreme in (c.max(), c.min()):
            hit = np.concatenate([[0], (c == extreme).astype(np.int8), [0]])
            edges = np.flatnonzero(np.diff(hit))
            out += sum(b - a for a, b in zip(edges[::2], edges[1::2], strict=True)
                       if b - a >= FLAT_RUN)
    return out


@pytest.mark.parametrize("steps_per_noise", [1.5, 3.0])
def test_a_quantised_quiet_log_has_no_flat_top(twin: dict, tmp_path: Path,
                                               steps_per_noise: float) -> None:
    """Voltages on a step 1.5 or 3 times their noise: the strongest press's slow peak is a run
    of one value at the channel's extreme (a rule on such runs alone would flag it, and
    extract drop the press); it is no clip, so nothing is flagged and every press is kept."""
    raw, _ = _near_clock(twin)
    raw.force.values = _quantised(raw.force.values, steps_per_noise)
    assert _flat_extremes(raw.force.values) > 0
    assert not on_rail(raw).any()
    res, out = _sync_variant(twin, tmp_path, raw)
    assert res.exit_code == 0, res.output
    assert "amplifier's rail" not in res.output, res.output
    states = tmp_path / "states.h5"
    res = _cli("extract", out, "--out", states, "--no-rrd")
    assert res.exit_code == 0, res.output
    assert _states_presses(states) == set(range(PRESSES))


PERIOD_S = 2.0       # a periodic trigger: a pulse every 2 s on both sides


def _periodic_trigger(raw: RawSession, truth: dict) -> RawSession:
    """A pulse every :data:`PERIOD_S` as mocap EVENTs over the whole recording, and 10 ms
    pulses in the force log at the true logger times, all but the first and last three that
    the log covers (so that whole periods tie)."""
    out = copy.deepcopy(raw)
    t_m = out.markers.time_ns * 1e-9
    events = np.arange(t_m[0] + 0.5, t_m[-1], PERIOD_S)
    to_logger = events * (1 + truth["drift_ppm"] * 1e-6) + truth["offset_s"]
    t_f = out.force.time_ns * 1e-9
    inside = to_logger[(to_logger > t_f[0] + 0.1) & (to_logger < t_f[-1] - 0.1)][3:-3]
    high = np.zeros(len(t_f), bool)
    for edge in inside:
        high |= (t_f >= edge) & (t_f < edge + 0.01)
    out.force.trigger = np.where(high, 5.0, 0.0)
    out.markers.events = [("Trigger", int(round(e * 1e9))) for e in events]
    out.trigger_event = "Trigger"
    return out


def test_a_periodic_trigger_takes_a_data_prior_that_fails_a_check(twin: dict) -> None:
    """A lock that fails a check the trigger session does not need (here a force-depth
    correlation of 0.99 asked for) still says which period, rather than asking for a trigger
    to be recorded."""
    raw = _periodic_trigger(twin["raw"], twin["truth"])
    res = sync_session(raw, SyncParams(min_correlation=0.99))
    assert res.clock.method == "trigger"
    assert abs(res.clock.offset_s - twin["truth"]["offset_s"]) <= 1e-3


def test_a_periodic_trigger_with_no_data_lock_is_refused_for_a_trigger(twin: dict) -> None:
    """Another session's force (its trigger pulses made periodic too): the tip motion cannot
    pick the period; the refusal speaks of the trigger, not of recording one."""
    raw = copy.deepcopy(twin["raw"])
    raw.force = copy.deepcopy(twin["other"].force)
    raw = _periodic_trigger(raw, twin["truth"])
    with pytest.raises(BadInput) as e:
        sync_session(raw)
    assert str(e.value.path).endswith("force.csv")
    assert "trigger: pulse train is periodic" in e.value.what, e.value.what
    assert "irregular intervals" in e.value.what and "record a trigger:" not in e.value.what

"""Sessions with holes: lost force samples and lost mocap frames are data, not a reason to
refuse. Against a twin session whose files had holes cut into them: every press away from a
hole keeps its states (to 0.05 mm of the same session without holes), no press a hole touches
gives a state, and each hole is named in one warning line.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner
from helpers.session_holes import (
    cut_force,
    cut_mocap,
    cut_qtm_tsv,
    press_spans_s,
    to_logger_s,
)

from core.holes import Hole, Timing
from core.recording import rrd_entities
from core.series import ForceSeries, MarkerSeries
from data_schema.synced import SYNCED
from pipeline.cli import cli
from sync.holes import BRIDGED, HoleSpan, bridge, bridgeable, leave_out_touched, regular_frames
from sync.presses import Press

MS = 1_000_000
STATE_TOL_M = 0.05e-3       # the target: states of presses away from a hole


# --- the step's parts ------------------------------------------------------------------------

def test_lost_frames_come_back_empty_at_their_times() -> None:
    """3 frames lost at 500 Hz: frames at their times with no marker, flagged as a kept hole;
    1 lost frame, bridged: back, not flagged (the gap filler fills it)."""
    t = np.r_[np.arange(5), np.arange(8, 10), np.arange(11, 13)] * 2 * MS
    xyz = np.arange(9 * 2 * 3, dtype=float).reshape(9, 2, 3)
    mk = MarkerSeries("m.tsv", t, ["a", "b"], xyz, 500.0)
    short = Hole(7, 18 * MS, 22 * MS, 2 * MS)
    timing = Timing(2 * MS, (Hole(5, 8 * MS, 16 * MS, 2 * MS), short))
    out, lost = regular_frames(mk, timing, [short])
    np.testing.assert_array_equal(out.time_ns, np.arange(13) * 2 * MS)
    assert np.isnan(out.positions[[5, 6, 7, 10]]).all()
    np.testing.assert_array_equal(out.positions[[0, 4, 8, 9, 11, 12]], xyz[[0, 4, 5, 6, 7, 8]])
    np.testing.assert_array_equal(np.flatnonzero(lost), [5, 6, 7])
    assert BRIDGED == 2


def test_a_short_force_hole_is_bridged_by_a_line_and_a_long_one_stays() -> None:
    """Two samples lost: filled on the straight line between the neighbours; 3 lost: kept."""
    t = np.r_[np.arange(10), np.arange(12, 20), np.arange(23, 30)] * MS
    v = np.column_stack([t / MS * 2.0, -t / MS])
    f = ForceSeries("f.csv", t, ["a", "b"], v, ["N", "N"], "wrench", 1000.0,
                    trigger=t / MS * 1.0)
    short = Hole(10, 9 * MS, 12 * MS, MS)
    assert bridgeable(short) and not bridgeable(Hole(18, 19 * MS, 23 * MS, MS))
    out = bridge(f, [short])
    np.testing.assert_array_equal(out.time_ns, np.r_[np.arange(20), np.arange(23, 30)] * MS)
    np.testing.assert_allclose(out.values[10:12], [[20, -10], [22, -11]])
    np.testing.assert_allclose(out.trigger[10:12], [10, 11])


def test_a_press_a_hole_reaches_is_left_out_and_kept_by_that_hole() -> None:
    """The loaded span widened by the reach: a hole 3 frames after a release touches it with a
    reach of 5 frames, not with 2."""
    presses = [Press(10, 20, 15), Press(40, 50, 45)]
    frames = np.zeros(60, bool)
    frames[52:55] = True
    for reach, kept in ((5, [presses[0]]), (2, presses)):
        span = HoleSpan("mocap", "m.tsv", Hole(52, 0, 1, 1.0), frames, 0.0)
        assert leave_out_touched(presses, [span], reach) == kept
        assert span.presses == [p for p in presses if p not in kept]


# --- twin sessions with holes cut into their files -------------------------------------------

def _stages(folder: Path, *synth: str) -> Path:
    for args in (("synth", folder / "s", "--seed", "3", "--locations", "2", "--repeats", "2",
                  *synth, "--no-rrd"),
                 ("ingest", folder / "s", "--out", folder / "s.mcap", "--no-rrd")):
        res = CliRunner().invoke(cli, ["-q", *map(str, args)])
        assert res.exit_code == 0, res.output + res.stderr
    _sync_extract(folder)
    return folder


def _sync_extract(folder: Path, rrd: bool = False) -> list[str]:
    """sync (with its recording when asked) and extract; the warning lines sync said."""
    rec = ["--rrd", str(folder / "synced.rrd")] if rrd else ["--no-rrd"]
    res = CliRunner().invoke(cli, ["-q", "sync", str(folder / "s.mcap"), "--out",
                                   str(folder / "synced.h5"), *rec])
    assert res.exit_code == 0, res.output + res.stderr
    ex = CliRunner().invoke(cli, ["-q", "extract", str(folder / "synced.h5"), "--out",
                                  str(folder / "states.h5"), "--no-rrd"])
    assert ex.exit_code == 0, ex.output + ex.stderr
    return [line for line in res.stderr.splitlines() if line.startswith("warning:")]


@pytest.fixture(scope="module")
def clean(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A twin session (4 presses at 2 places, force from a 1 kHz CSV log) without holes."""
    return _stages(tmp_path_factory.mktemp("clean"))


@pytest.fixture(scope="module")
def clean_analog(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The same with the force through the mocap's analog board (QTM's analog TSV export,
    the mocap's clock): the stream `pipeline live` records."""
    return _stages(tmp_path_factory.mktemp("analog"), "--force-via", "analog",
                   "--force-file", "tsv")


def _presses_by_rest_tip(states: Path) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Each press's (steps, points) of a states file, keyed by its sequence."""
    with h5py.File(states) as f:
        seq, step, pts = f["states/sequence"][()], f["states/step"][()], f["states/points"][()]
    return {int(s): (step[seq == s], pts[seq == s]) for s in np.unique(seq)}


def _compare(clean: Path, holed: Path, spans: np.ndarray, holes_s: list[tuple[float, float]]
             ) -> None:
    """Every press the holed session keeps is one of the clean session's, with the same
    levels and points within 0.05 mm; a press a hole falls in (true spans, mocap clock,
    widened by 0.2 s) is not kept; a press 1 s or more from every hole is."""
    def near(k: int, by: float) -> bool:
        a, b = spans[k]
        return any(a - by < h1 and h0 < b + by for h0, h1 in holes_s)

    before, after = _presses_by_rest_tip(clean / "states.h5"), _presses_by_rest_tip(
        holed / "states.h5")
    assert sorted(before) == list(range(len(spans)))
    rest = {k: points[0, -1] for k, (_, points) in before.items()}
    kept = []
    for steps, points in after.values():
        k = min(rest, key=lambda j: np.linalg.norm(rest[j] - points[0, -1]))
        kept.append(k)
        ref_steps, ref_points = before[k]
        np.testing.assert_array_equal(steps, ref_steps)
        off = np.linalg.norm(points - ref_points, axis=2)
        assert np.nanmax(off) < STATE_TOL_M, (k, np.nanmax(off))
    assert len(set(kept)) == len(kept)
    assert not [k for k in kept if near(k, 0.2)], kept
    assert {k for k in before if not near(k, 1.0)} <= set(kept), kept


def _holed_copy(src: Path, dst: Path) -> Path:
    dst.mkdir()
    shutil.copytree(src / "s", dst / "s")
    return dst


def _mid(spans: np.ndarray, k: int) -> float:
    return float(spans[k].mean())


def _between(spans: np.ndarray, k: int) -> float:
    return float(spans[k, 1] + spans[k + 1, 0]) / 2


def _ingest(folder: Path) -> None:
    res = CliRunner().invoke(cli, ["-q", "ingest", str(folder / "s"), "--out",
                                   str(folder / "s.mcap"), "--no-rrd"])
    assert res.exit_code == 0, res.output + res.stderr


# (force hole: where, length s), (mocap hole: where, length s); where = "pK" inside press K,
# "bK" between presses K and K + 1
CASES = {
    "force 50 ms in a press, mocap 0.6 s between presses": (("p0", 0.05), ("b2", 0.6)),
    "force 0.5 s between presses, mocap 0.4 s in a press": (("b0", 0.5), ("p2", 0.4)),
    "force 5 s over a press": (("b1", 5.0), None),
}


@pytest.mark.parametrize("case", list(CASES))
def test_a_session_with_holes_keeps_every_press_away_from_them(
        case: str, clean: Path, tmp_path: Path) -> None:
    folder = _holed_copy(clean, tmp_path / "holed")
    truth = folder / "s" / "truth.h5"
    spans = press_spans_s(truth)
    holes_s, files = [], []
    for kind, hole in zip(("force", "mocap"), CASES[case], strict=True):
        if hole is None:
            continue
        where, length = hole
        at = (_mid if where[0] == "p" else _between)(spans, int(where[1:]))
        if kind == "force":
            assert cut_force(folder / "s", to_logger_s(truth, at), length) > 0
            files.append("force.csv")
        else:
            assert cut_mocap(folder / "s", at, length) > 0
            files.append("indentation.tsv")
        holes_s.append((at, at + length))
    _ingest(folder)
    lines = _sync_extract(folder, rrd=True)
    assert len(lines) == len(files), lines
    for name in files:
        assert sum(f"/{name}: " in line and " lost (" in line for line in lines) == 1, lines
    _compare(clean, folder, spans, holes_s)
    with h5py.File(folder / "synced.h5") as f:
        assert f.attrs["schema_version"] == SYNCED.version      # 1.4 brought the holes
        recorded = json.loads(f.attrs["holes"])
        assert sorted(h["stream"] for h in recorded) == sorted(
            "force" if n == "force.csv" else "mocap" for n in files)
    assert "/quality/hole" in rrd_entities(folder / "synced.rrd")


def test_lost_frames_of_a_capture_through_the_analog_board(clean_analog: Path,
                                                           tmp_path: Path) -> None:
    """A real-time capture that lost 0.3 s inside a press loses it in every export of it: the
    3D, 6D and analog TSVs (force on the mocap's clock). That press is left out, the others
    keep their states; the hole is named once per stream."""
    folder = _holed_copy(clean_analog, tmp_path / "holed")
    spans = press_spans_s(folder / "s" / "truth.h5")
    at = _mid(spans, 1)
    frames = cut_mocap(folder / "s", at, 0.3)
    samples = cut_qtm_tsv(folder / "s" / "indentation_a.tsv", at, 0.3)
    assert frames == 150 and samples == 300
    _ingest(folder)
    lines = _sync_extract(folder)
    assert len(lines) == 2 and "indentation.tsv: 0.300 s of mocap frames lost (150 frames)" \
        in lines[0] and "indentation_a.tsv: 0.300 s of force samples lost (300 samples)" \
        in lines[1], lines
    _compare(clean_analog, folder, spans, [(at, at + 0.3)])


def test_jittered_mocap_times_are_still_refused(clean: Path, tmp_path: Path) -> None:
    """A frame written 1.5 ms late at 500 Hz (steps of 3.5 and 0.5 ms: no whole frame lost):
    jitter, refused in one line naming the file and the line."""
    folder = _holed_copy(clean, tmp_path / "jitter")
    path = folder / "s" / "indentation.tsv"
    lines = path.read_text().splitlines(keepends=True)
    row = next(i for i, line in enumerate(lines) if line.startswith("Frame\t")) + 200
    fields = lines[row].split("\t")
    fields[1] = f"{float(fields[1]) + 0.0015:.5f}"
    lines[row] = "\t".join(fields)
    path.write_text("".join(lines))
    res = CliRunner().invoke(cli, ["-q", "ingest", str(folder / "s"), "--out",
                                   str(folder / "s.mcap"), "--no-rrd"])
    assert res.exit_code == 2
    (line,) = res.stderr.strip().splitlines()
    assert f"indentation.tsv:line {row + 1}" in line and "jitter" in line, line


def _truth_onsets_s(truth: Path) -> np.ndarray:
    """Each true press's first loaded frame (the true force above 0.05 N), mocap clock."""
    with h5py.File(truth) as t:
        times, force, press = t["mocap/time_s"][()], t["force/magnitude"][()], \
            t["mocap/press"][()]
    return np.array([times[(press == k) & (force > 0.05)][0] for k in np.unique(press[press >= 0])])


def test_a_hole_just_before_a_press_keeps_it_out_of_the_states(clean: Path, tmp_path: Path
                                                               ) -> None:
    """6 mocap frames lost 0.25 s before a press's contact: inside the rest its first state
    is read from, so that press is left out (not kept with a wrong rest state); and 2 lost
    force samples (bridged) elsewhere cost nothing, named in their own line."""
    folder = _holed_copy(clean, tmp_path / "holed")
    truth = folder / "s" / "truth.h5"
    onset = _truth_onsets_s(truth)[2]
    assert cut_mocap(folder / "s", onset - 0.262, 0.012) == 6
    spans = press_spans_s(truth)
    two = _mid(spans, 0)
    assert cut_force(folder / "s", to_logger_s(truth, two), 0.002) == 2
    _ingest(folder)
    lines = _sync_extract(folder)
    assert len(lines) == 2, lines
    bridged = [line for line in lines if "force.csv" in line]
    assert "bridged by a straight line" in bridged[0] and "no press left out" in bridged[0]
    with h5py.File(folder / "synced.h5") as f:
        recorded = json.loads(f.attrs["holes"])
    assert sorted((h["stream"], h["bridged"]) for h in recorded) == \
        [("force", True), ("mocap", False)]
    _compare(clean, folder, spans, [(onset - 0.262, onset - 0.25)])
    assert len(_presses_by_rest_tip(folder / "states.h5")) == len(spans) - 1


def test_a_pause_that_is_no_whole_number_of_samples_is_a_hole_not_jitter() -> None:
    """A 1 kHz log paused for 2.4 periods: not bridged (no sample fits it), kept as a hole,
    and the log is not refused as jittered."""
    t = np.r_[np.arange(100), 101.4 + np.arange(100)] * MS
    mk = MarkerSeries("m.tsv", np.arange(50) * 2 * MS, ["a"], np.zeros((50, 1, 3)), 500.0)
    f = ForceSeries("f.csv", t.astype(np.int64), ["a"], np.zeros((200, 1)), ["N"], "wrench",
                    1000.0)
    from core.series import RawSession
    from sync.holes import session_holes

    raw, holes = session_holes(RawSession("s", mk, f, ["a"], []), 0.02)
    assert [h.index for h in holes.force] == [100] and not holes.bridged_force
    np.testing.assert_array_equal(raw.force.time_ns, f.time_ns)


def test_a_marker_gap_that_runs_into_a_hole_is_not_filled() -> None:
    """Two frames of one marker missing just before 3 lost frames: 5 frames, under 20 ms, but
    nothing was recorded in the hole: they stay missing."""
    from sync.gaps import MISSING, fill_gaps

    t = np.arange(40) * 2e-3
    x = np.tile(np.arange(40, dtype=float)[:, None, None], (1, 1, 3))
    x[18:23] = np.nan
    lost = np.zeros(40, bool)
    lost[20:23] = True
    out, flags = fill_gaps(t, x, 0.02, never=lost)
    assert np.isnan(out[18:23]).all() and (flags[18:23, 0] == MISSING).all()
    out, _ = fill_gaps(t, x, 0.02)
    np.testing.assert_allclose(out[18:23, 0, 0], np.arange(18, 23), atol=1e-9)


def test_a_hole_in_the_analog_export_alone_is_not_another_capture(clean_analog: Path,
                                                                  tmp_path: Path) -> None:
    """0.1 s cut from the analog TSV only (the 3D export whole): ingest takes it as the same
    capture with a hole, and sync names it."""
    folder = _holed_copy(clean_analog, tmp_path / "holed")
    at = _between(press_spans_s(folder / "s" / "truth.h5"), 0)
    assert cut_qtm_tsv(folder / "s" / "indentation_a.tsv", at, 0.1) == 100
    _ingest(folder)
    (line,) = _sync_extract(folder)
    assert "indentation_a.tsv: 0.100 s of force samples lost (100 samples)" in line, line

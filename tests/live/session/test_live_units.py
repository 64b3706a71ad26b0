"""The live session's parts on hand-made input: the journal cut short, the session's checks
against QTM's labels and analog board (force plates: test_live_plate.py), and the presses found
sample by sample."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.errors import BadInput
from data_schema.session import read_session
from live.protocol.parameters import AnalogDevice, QtmParameters
from live.session.journal import FORCE, MARKERS, Journal, read_journal
from live.session.layout import live_layout
from live.session.presses import PressTracker
from sync.presses import MERGE_S, MIN_PRESS_S, PressRule, segment_presses
from sync.sync_params import SyncParams

SOURCE = "QTM RT 127.0.0.1:1"


def test_the_journal_keeps_every_complete_block_of_a_file_cut_short(tmp_path: Path) -> None:
    path = tmp_path / "session.mcap.part"
    journal = Journal(path, {"labels": ["a"], "channels": ["c0", "c1"]})
    for i in range(3):
        journal.append(MARKERS, np.arange(i * 5, i * 5 + 5) * 2_000_000, np.full((5, 3), i))
        before = path.stat().st_size
        journal.append(FORCE, np.arange(i * 10, i * 10 + 10) * 1_000_000, np.full((10, 2), i))
    cut = (before + path.stat().st_size) // 2   # the last block cut short, as by a kill
    journal.close()
    whole = read_journal(path)
    assert whole.complete and len(whole.streams[MARKERS][0]) == 15
    assert (whole.blocks, whole.cut_bytes) == (6, 0)
    np.testing.assert_array_equal(whole.streams[MARKERS][0], np.arange(15) * 2_000_000)
    (tmp_path / "cut.part").write_bytes(path.read_bytes()[:cut])
    part = read_journal(tmp_path / "cut.part")
    assert not part.complete and (part.blocks, part.cut_bytes) == (5, cut - before)
    assert len(part.streams[MARKERS][0]) == 15 and len(part.streams[FORCE][0]) == 20
    (tmp_path / "other.part").write_bytes(b"\x89MCAP0\r\n")
    with pytest.raises(BadInput, match="not a live session's journal"):
        read_journal(tmp_path / "other.part")


def test_the_session_is_held_against_qtms_labels_and_boards(twin_session: Path) -> None:
    cfg = read_session(twin_session)
    labels = cfg.mocap.phantom_markers + cfg.mocap.indenter_markers + ["stray"]
    gauges = AnalogDevice(2, "USB-2533", 1000.0, list(cfg.force.channels), ["V"] * 6)
    emg = AnalogDevice(1, "EMG", 2000.0, ["e0", "e1"], ["V", "V"])
    assert live_layout(QtmParameters(SOURCE, 500.0, labels, [emg, gauges]), cfg).device == gauges
    with pytest.raises(BadInput, match="not in file: P03"):
        live_layout(QtmParameters(SOURCE, 500.0, [n for n in labels if n != "P03"],
                                  [gauges]), cfg)
    newtons = AnalogDevice(2, "USB-2533", 1000.0, list(cfg.force.channels), ["N"] * 6)
    with pytest.raises(BadInput, match="is in N as the file states, but force.units says V"):
        live_layout(QtmParameters(SOURCE, 500.0, labels, [newtons]), cfg)
    with pytest.raises(BadInput, match="no analog board"):
        live_layout(QtmParameters(SOURCE, 500.0, labels, []), cfg)


def test_presses_are_found_as_the_samples_arrive() -> None:
    """Three raised cosines on a 1 kHz force, fed a frame (2 samples) at a time: peaks 6, 0.4
    (below detect: a touch) and 3 N, a flicker below contact inside the first (one contact)."""
    rate, t = 1000.0, np.arange(12000) / 1000.0
    force = np.zeros_like(t)
    for start, peak in ((1.0, 6.0), (5.0, 0.4), (8.0, 3.0)):
        inside = (t >= start) & (t < start + 2.0)
        force[inside] = peak * 0.5 * (1 - np.cos(np.pi * (t[inside] - start)))
    force[1500:1510] = 0.0                        # 10 ms below contact: the same contact
    tracker, done = PressTracker(rate, PressRule(SyncParams().detect_n, SyncParams().contact_n)), []
    times = np.round(t * 1e9).astype(np.int64)
    for i in range(0, len(t), 2):
        done += tracker.add(times[i:i + 2], force[i:i + 2])
    assert [d.number for d in done] == [1, 2]
    assert [round(d.peak_n, 3) for d in done] == [6.0, 3.0]
    assert [d.peak_ns for d in done] == [2_000_000_000, 9_000_000_000]
    assert abs(done[0].start_ns - 1.0e9) < 0.2e9 and abs(done[1].end_ns - 10.0e9) < 0.2e9


def test_the_stream_and_the_whole_series_find_presses_by_one_rule() -> None:
    """Flat contacts at 1 kHz (a touch shorter than MIN_PRESS_S, contacts a flicker shorter
    than MERGE_S apart, two further apart, one below the detection level), fed to the tracker
    a frame (4 samples) at a time and to sync's segmentation whole: the same four presses,
    where they were made."""
    rate, level = 1000.0, SyncParams().detect_n
    contacts = [(1.0, 1.0 + 0.5 * MIN_PRESS_S, 4 * level), (2.0, 2.5, 4 * level),
                (4.0, 4.4, 6 * level), (4.4 + 0.5 * MERGE_S, 4.8, 4 * level),
                (6.0, 6.4, 4 * level), (6.4 + 2 * MERGE_S, 6.8, 8 * level),
                (8.0, 10.0, 0.5 * level)]
    truth = [(2.0, 2.5), (4.0, 4.8), (6.0, 6.4), (6.4 + 2 * MERGE_S, 6.8)]
    force = np.zeros(12000)
    for start, stop, f in contacts:
        force[round(start * rate):round(stop * rate)] = f
    rule = PressRule(SyncParams().detect_n, SyncParams().contact_n)
    tracker, done = PressTracker(rate, rule), []
    times = np.arange(len(force)) * 1_000_000
    for i in range(0, len(force), 4):
        done += tracker.add(times[i:i + 4], force[i:i + 4])
    whole, _ = segment_presses(force, rate, rule)
    assert [(d.start_ns, d.end_ns + 1_000_000) for d in done] == \
        [(round(a * 1e9), round(b * 1e9)) for a, b in truth]
    assert [(p.onset, p.release) for p in whole] == \
        [(round(a * rate), round(b * rate)) for a, b in truth]
    assert [d.peak_n for d in done] == [4 * level, 6 * level, 4 * level, 8 * level]


def test_the_stream_and_the_whole_series_agree_at_the_shortest_press() -> None:
    """A contact of exactly MIN_PRESS_S at 1 kHz is a press for both; one sample shorter is
    one for neither."""
    rate = 1000.0
    rule = PressRule(SyncParams().detect_n, SyncParams().contact_n)
    shortest = round(MIN_PRESS_S * rate)
    for samples, pressed in ((shortest, 1), (shortest - 1, 0)):
        force = np.zeros(3000)
        force[1000:1000 + samples] = 4 * SyncParams().detect_n
        tracker = PressTracker(rate, rule)
        done = tracker.add(np.arange(len(force)) * 1_000_000, force)
        whole, _ = segment_presses(force, rate, rule)
        assert (len(done), len(whole)) == (pressed, pressed)

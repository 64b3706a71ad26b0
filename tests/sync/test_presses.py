"""Press segmentation and location/repeat numbering on synthetic force and tip tracks."""

from __future__ import annotations

import numpy as np

from sync.presses import MERGE_S, MIN_PRESS_S, PressRule, assign_locations, segment_presses
from sync.sync_params import SyncParams

RATE = 500.0
RULE = PressRule(SyncParams().detect_n, SyncParams().contact_n)   # sync's press and contact levels
RADIUS = SyncParams().location_radius_m


def _force(onsets: list[float], lengths: list[float], seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(0, 30, 1 / RATE)
    f = rng.normal(0, 0.01, len(t))
    for on, length in zip(onsets, lengths, strict=True):
        s = (t - on) / length
        inside = (s >= 0) & (s <= 1)
        f[inside] += 6.0 * np.sin(np.pi * s[inside]) ** 2
    return f


def test_presses_found_from_onset_to_release() -> None:
    onsets, lengths = [2.0, 8.5, 15.0], [2.0, 3.0, 2.5]
    presses, cut = segment_presses(_force(onsets, lengths), RATE, RULE)
    assert len(presses) == 3 and cut == 0
    for p, on, length in zip(presses, onsets, lengths, strict=True):
        # 6 sin^2(pi s) passes 0.05 N at s = asin(sqrt(0.05/6))/pi ~ 0.029
        lead = np.arcsin(np.sqrt(0.05 / 6)) / np.pi * length
        assert abs(p.onset / RATE - (on + lead)) < 0.02
        assert abs(p.release / RATE - (on + length - lead)) < 0.02
        assert abs(p.peak / RATE - (on + length / 2)) < 0.05


def test_noise_spikes_and_short_touches_are_not_presses() -> None:
    f = _force([5.0, 12.0], [0.1, 2.0])            # a 0.1 s touch, then a press
    f[3000] = 1.0                                   # one spike
    f[np.arange(10)] = np.nan                       # unknown frames count as unloaded
    presses, cut = segment_presses(f, RATE, RULE)
    assert len(presses) == 1 and abs(presses[0].peak / RATE - 13.0) < 0.05 and cut == 0


def test_presses_cut_off_by_the_ends_are_left_out_and_counted() -> None:
    """A press running into either end of the series, or into unknown force, has no known
    onset or release: it is counted, not returned."""
    f = _force([2.0, 8.5, 15.0, 27.0], [2.0, 3.0, 2.5, 2.0])
    whole, cut = segment_presses(f, RATE, RULE)
    assert len(whole) == 4 and cut == 0
    start = int(3.0 * RATE)                         # the recording starts inside press 0
    end = int(28.0 * RATE)                          # and ends inside press 3
    presses, cut = segment_presses(f[start:end], RATE, RULE)
    assert cut == 2 and len(presses) == 2
    assert [p.onset + start for p in presses] == [p.onset for p in whole[1:3]]
    g = f.copy()
    g[int(16.0 * RATE):] = np.nan                   # the force log ends inside press 2
    presses, cut = segment_presses(g, RATE, RULE)
    assert cut == 1 and [p.onset for p in presses] == [p.onset for p in whole[:2]]


def test_locations_and_repeats_in_press_order() -> None:
    centres = np.array([[0, 0], [0.03, 0], [0.001, 0.002], [0.031, -0.001], [0.0, 0.03],
                        [-0.002, 0.0]])
    loc, rep, means = assign_locations(centres, RADIUS)
    np.testing.assert_array_equal(loc, [0, 1, 0, 1, 2, 0])
    np.testing.assert_array_equal(rep, [0, 0, 1, 1, 0, 2])
    np.testing.assert_allclose(means[0], centres[[0, 2, 5]].mean(axis=0))
    loc, rep, _ = assign_locations(np.array([[np.nan, 0.0], [0.0, 0.0]]), RADIUS)
    np.testing.assert_array_equal(loc, [-1, 0])


def _boxes(spans_s: list[tuple[float, float, float]], rate: float, length_s: float = 12.0
           ) -> np.ndarray:
    """A force of flat contacts: (start s, stop s, N) each, zero between."""
    f = np.zeros(int(length_s * rate))
    for start, stop, level in spans_s:
        f[int(round(start * rate)):int(round(stop * rate))] = level
    return f


# a touch too short, a press, two contacts a flicker apart (one press), two contacts further
# apart (two presses), a long contact that never rises above the detection level
CONTACTS = [(1.0, 1.0 + 0.75 * MIN_PRESS_S, 2.0), (2.0, 2.5, 2.0),
            (4.0, 4.4, 3.0), (4.4 + 0.5 * MERGE_S, 4.8, 2.0),
            (6.0, 6.4, 2.0), (6.4 + 2.0 * MERGE_S, 6.8, 4.0),
            (8.0, 10.0, 0.5 * SyncParams().detect_n)]
PRESSES_S = [(2.0, 2.5), (4.0, 4.8), (6.0, 6.4), (6.4 + 2.0 * MERGE_S, 6.8)]


def test_the_rule_merges_flicker_and_drops_touches_and_light_contacts() -> None:
    """Flat contacts of known spans: a press is a contact (gaps shorter than MERGE_S bridged)
    lasting MIN_PRESS_S and rising above the detection level, from its first loaded sample to
    one past its last."""
    presses, cut = segment_presses(_boxes(CONTACTS, RATE), RATE, RULE)
    assert cut == 0
    assert [(p.onset, p.release) for p in presses] == \
        [(int(round(a * RATE)), int(round(b * RATE))) for a, b in PRESSES_S]
    assert [p.peak for p in presses] == [int(2.0 * RATE), int(4.0 * RATE), int(6.0 * RATE),
                                         int(round((6.4 + 2.0 * MERGE_S) * RATE))]

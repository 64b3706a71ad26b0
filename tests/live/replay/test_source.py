"""What the replay serves of a session: the session's markers in mm in session order, and the
force as an analog device whose samples each go to one frame, by time; a log on its own clock
loses (and counts) what lies outside the frames."""

from __future__ import annotations

import numpy as np
from helpers.raw_sessions import analytic_session

from live.replay.parameters import parameters_xml
from live.replay.source import apportion, replay_source


def test_shared_clock_gives_each_frame_its_own_samples():
    frames = np.arange(4) * 2_000_000                  # 500 Hz
    samples = np.arange(8) * 1_000_000                 # 1 kHz on the same clock
    np.testing.assert_array_equal(apportion(samples, frames, 500.0, 1000.0), [0, 2, 4, 6, 8])
    late = samples - 1                                 # a nanosecond's rounding changes nothing
    np.testing.assert_array_equal(apportion(late, frames, 500.0, 1000.0), [0, 2, 4, 6, 8])


def test_a_log_on_its_own_clock_is_cut_to_the_frames():
    s = analytic_session()                             # a wrench log 0.8 s late, 1 s longer
    src = replay_source(s, "analytic")
    a, f = src.force, s.force
    assert src.labels == s.phantom_markers + s.indenter_markers and src.clock == "log"
    np.testing.assert_array_equal(src.markers_mm, np.float32(s.markers.positions * 1e3))
    assert a.labels == f.channels + ["trigger"] and a.units[:4] == ["newtons"] * 3 + [
        "newtonmetre"] and a.units[-1] == "V"
    t = f.time_ns[a.first_sample:a.first_sample + len(a.values)]
    assert t[0] >= -500_000 and t[-1] < s.markers.time_ns[-1] + 2_000_000 - 500_000
    assert a.left_out == f.frames - len(a.values) > 0
    np.testing.assert_array_equal(a.values[:, :6], np.float32(f.values[a.first_sample:][
        :len(a.values)]))
    first, values = a.samples(10, 12)                  # frames 10 and 11: 4 samples
    assert first == a.first_sample + 20 and values.shape == (4, 7)
    assert "<Channel>\n        <Label>Fx</Label>\n        <Unit>newtons</Unit>" in \
        parameters_xml(src, ["analog"], "1.25")

"""The demo's profile: the host's figure read from the tool's own line, the demo's time in host
figures, the quick demo's target in them, and each stage's time summed from its steps."""

from __future__ import annotations

from pathlib import Path

import pytest

import pipeline.demo_times as demo_times
from core.host_speed import LINE, parse_line
from pipeline.demo_plan import Step
from pipeline.demo_targets import QUICK_HOST_UNITS, _quick_time
from pipeline.demo_times import HostFigure, Times


def test_the_figure_is_read_from_the_tools_line():
    assert parse_line("warming\n" + LINE.format(3.364, "2.13.0+cpu") + "\n") == 3.36
    assert parse_line("host_speed: 4.87 s (median of 3; torch 2.13.0)") == 4.87
    assert parse_line("no figure here") is None
    assert parse_line("host_speed: fast") is None


def test_without_a_way_to_measure_the_figure_is_absent_and_said(monkeypatch):
    monkeypatch.setattr(demo_times.sys, "executable", "/nonexistent/python")
    host = demo_times.measure_host()
    assert host.seconds is None and host.note.startswith("absent")
    assert host.multiple(100.0) is None


def test_quick_time_target_is_85_host_figures():
    assert QUICK_HOST_UNITS == 85
    ok, missed = _quick_time(84 * 3.0, 3.0), _quick_time(86 * 3.0, 3.0)
    assert ok[1] and not missed[1]
    assert "84 x the host's figure (3.00 s)" in ok[2]
    assert _quick_time(299.0, None)[1] and not _quick_time(301.0, None)[1]   # 5 min without


def _step(command: str, out: str, *more: str) -> Step:
    return Step((command, *more), (), (Path(out),))


def test_stages_sum_their_steps_and_count_skips():
    times = Times()
    times.step(_step("train", "a/best.pt"), 10.0, "worker 0")
    times.step(_step("train", "b/best.pt"), 2.5, "worker 1")
    times.step(_step("eval", "s.json", "--scarcity"), 4.0, "worker 0")
    times.step(_step("sync", "x.h5"), 0.0, "demo", skipped=True)
    times.batch([_step("train", "a/best.pt")], 11.0, 2)
    doc = times.document(30.0, 1.0, HostFigure(3.0, "host_speed: 3.00 s"), 2, 1)
    assert doc["stages"] == {"train": {"seconds": 12.5, "ran": 2, "skipped": 0},
                             "eval --scarcity": {"seconds": 4.0, "ran": 1, "skipped": 0},
                             "sync": {"seconds": 0.0, "ran": 0, "skipped": 1}}
    assert doc["total_host_units"] == 10.0 and doc["host_speed_s"] == 3.0
    assert [s["where"] for s in doc["steps"]] == ["worker 0", "worker 1", "worker 0", "demo"]
    assert doc["batches"] == [{"stages": ["train"], "steps": 1, "workers": 2, "wall_s": 11.0}]
    absent = times.document(30.0, 1.0, HostFigure(None, "absent: not measured"), 2, 1)
    assert absent["total_host_units"] is None and absent["host_speed"].startswith("absent")


@pytest.mark.slow
def test_the_figure_is_measured_by_the_shared_method():
    host = demo_times.measure_host()
    assert host.seconds is not None and host.seconds > 0, host.note
    assert host.note.startswith("host_speed: ")

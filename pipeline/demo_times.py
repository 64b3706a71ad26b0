"""The demo's profile, ``demo_times.json``: how long each stage and each step took (wall
seconds), beside the host's figure (:mod:`core.host_speed`, the method of the shared
``host_speed.py``) so that two machines' times compare.

The figure is measured in a process of its own (one thread, as the tool does) before the
steps run, and is left out of the demo's time; where it cannot be measured the document says
why and gives no multiple.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import core
from core.host_speed import ONE_THREAD, parse_line
from pipeline.demo_plan import Step

SCHEMA = ("phantom.demo_times", "1.0")
TIMES = "demo_times.json"       # in the demo's folder


@dataclass(frozen=True)
class HostFigure:
    """The host's figure (s), or None with the reason in ``note``; ``cost_s``: the time the
    measurement took."""

    seconds: float | None
    note: str
    cost_s: float = 0.0

    def multiple(self, seconds: float) -> float | None:
        """``seconds`` in host units (None without a figure)."""
        return None if self.seconds is None else seconds / self.seconds


def measure_host(timeout_s: float = 600.0) -> HostFigure:
    """The host's figure, from ``python -m core.host_speed`` in a process of one thread."""
    root = str(Path(core.__file__).resolve().parent.parent)
    env = {**os.environ, **ONE_THREAD,
           "PYTHONPATH": os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")]))}
    tic = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, "-m", "core.host_speed"], env=env,
                              capture_output=True, text=True, timeout=timeout_s, check=False)
    except (OSError, subprocess.SubprocessError) as e:
        return HostFigure(None, f"absent: the host's figure could not be measured ({e})")
    cost = time.perf_counter() - tic
    figure = parse_line(proc.stdout)
    if proc.returncode != 0 or figure is None:
        why = (proc.stderr.strip().splitlines() or [f"exit status {proc.returncode}"])[-1]
        return HostFigure(None, f"absent: core.host_speed failed ({why})", cost)
    return HostFigure(figure, proc.stdout.strip(), cost)


def stage_of(step: Step) -> str:
    """The stage a step's time counts to: the plan's name for it, else its command (the
    scarcity study apart)."""
    return step.stage or step.args[0] + (" --scarcity" if "--scarcity" in step.args else "")


@dataclass
class Times:
    """The wall times of the demo's steps and batches, as they end."""

    steps: list[dict] = field(default_factory=list)
    batches: list[dict] = field(default_factory=list)

    def step(self, step: Step, seconds: float, where: str, skipped: bool = False) -> None:
        """One step's time (0 when skipped), and where it ran ("demo", "worker K")."""
        self.steps.append({"stage": stage_of(step), "output": str(step.outputs[0]),
                           "seconds": round(seconds, 3), "skipped": skipped, "where": where,
                           "args": list(step.args)})

    def batch(self, steps: list[Step], seconds: float, workers: int) -> None:
        """A batch's wall time, its steps' stages and how many ran side by side."""
        self.batches.append({"stages": sorted({stage_of(s) for s in steps}),
                             "steps": len(steps), "workers": workers,
                             "wall_s": round(seconds, 3)})

    def stages(self) -> dict[str, dict]:
        """Per stage: the summed wall time of its steps, how many ran and were skipped."""
        out: dict[str, dict] = {}
        for s in self.steps:
            row = out.setdefault(s["stage"], {"seconds": 0.0, "ran": 0, "skipped": 0})
            row["seconds"] = round(row["seconds"] + s["seconds"], 3)
            row["skipped" if s["skipped"] else "ran"] += 1
        return out

    def document(self, total_s: float, summary_s: float, host: HostFigure, jobs: int,
                 threads: int) -> dict:
        """``demo_times.json``: the total (and in host units), per stage, per batch, per
        step."""
        units = host.multiple(total_s)
        return {"schema": SCHEMA[0], "schema_version": SCHEMA[1],
                "total_s": round(total_s, 3),
                "host_speed_s": host.seconds, "host_speed": host.note,
                "host_speed_cost_s": round(host.cost_s, 3),
                "total_host_units": None if units is None else round(units, 2),
                "jobs": jobs, "threads_per_worker": threads,
                "summary_s": round(summary_s, 3), "stages": self.stages(),
                "batches": self.batches, "steps": self.steps}

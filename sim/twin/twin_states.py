"""The true static states of a synthetic session: every 0.5 N of each press's loading phase,
exactly as the phantom model solved them, with the time the loading force first reached each."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core.protocol import STEP_N, top_level
from sim.twin.indenter import Hand
from sim.twin.phantom import LoadPath
from sim.twin.twin_mocap import Mocap
from sim.twin.twin_scene import Lab


@dataclass
class TrueStates:
    """True static states every 0.5 N of each press's loading phase."""

    points: np.ndarray          # (S, N + 1, 3): the N phantom markers, then the tip
    force: np.ndarray           # (S,)
    force_vector: np.ndarray    # (S, 3)
    step: np.ndarray
    press: np.ndarray
    location: np.ndarray
    time_s: np.ndarray


def true_states(hand: Hand, paths: list[LoadPath], lab: Lab, mocap: Mocap) -> TrueStates:
    """The static state at every level of each press, from the solved load paths."""
    rows: dict[str, list] = {k: [] for k in ("points", "force", "vector", "step", "press",
                                             "location", "time")}
    for k, (press, path) in enumerate(zip(hand.presses, paths, strict=True)):
        frames = np.flatnonzero(mocap.press == k)
        loading = frames[mocap.time_s[frames] <= press.times[4] + 1e-9]
        f, t = mocap.force[loading], mocap.time_s[loading]
        for step in range(top_level(press.fmax, STEP_N) + 1):
            level = step * STEP_N
            i = int(np.flatnonzero(np.isclose(path.forces, level, atol=1e-9))[0])
            rows["points"].append(np.concatenate([lab(path.markers[i]), lab(path.tip[i])[None]]))
            rows["force"].append(level)
            rows["vector"].append(level * press.direction)
            rows["step"].append(step)
            rows["press"].append(k)
            rows["location"].append(press.location)
            rows["time"].append(press.times[3] if step == 0 else _crossing(t, f, level))
    return TrueStates(points=np.array(rows["points"]), force=np.array(rows["force"]),
                  force_vector=np.array(rows["vector"]), step=np.array(rows["step"]),
                  press=np.array(rows["press"]), location=np.array(rows["location"]),
                  time_s=np.array(rows["time"], dtype=np.float64))


def _crossing(t: np.ndarray, f: np.ndarray, level: float) -> float:
    """First time the sampled force reaches ``level`` (linear between frames)."""
    hit = np.flatnonzero(f >= level)
    if hit.size == 0:
        return float(t[-1]) if t.size else float("nan")
    i = int(hit[0])
    if i == 0:
        return float(t[0])
    return float(t[i - 1] + (level - f[i - 1]) / (f[i] - f[i - 1]) * (t[i] - t[i - 1]))

"""Small analytic states files for the cGNN tests: a surface dented under a moving tip.

A 7 x 7 grid of points on [0, 0.1]^2 (z = 0) is pressed by a tip at one of a few places; at
level t the tip sits t mm deep and every point sinks by ``t mm * exp(-r^2 / (2 * 15 mm^2))``
(r: its distance from the tip in the plane), and the force is 0.5 N * t. The truth is known in
closed form, so a model that learns it is measured against it, not against itself.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from data_schema.hdf5 import write_h5
from data_schema.states import STATES
from extract.static_states import example_pairs
from split.split_stage import build_manifest, default_plan, write_manifest
from train.model.config import CGNNConfig

TINY = CGNNConfig(edge_widths=((8, 8),) * 3, disp_widths=(16,), force_widths=(8, 8, 8))  # fast
SIGMA = 0.015
GRID = 7
DENT_NAMES = [f"D{k:02d}" for k in range(GRID * GRID)]   # the dent file's point names


def dent(rest: np.ndarray, tip_xy: np.ndarray, depth: float) -> np.ndarray:
    """The dented surface (N, 3) for a tip at ``tip_xy`` pressed ``depth`` metres."""
    r2 = ((rest[:, :2] - tip_xy) ** 2).sum(1)
    out = rest.copy()
    out[:, 2] -= depth * np.exp(-r2 / (2 * SIGMA**2))
    return out


def write_dent_states(path: Path, places: int = 4, repeats: int = 2, steps: int = 5,
                      seed: int = 0) -> dict[str, np.ndarray]:
    """A phantom.states 2.1 file of the dent model (points named); returns its arrays."""
    rng = np.random.default_rng(seed)
    g = (np.arange(GRID) + 0.5) / GRID * 0.1
    rest = np.stack([*np.meshgrid(g, g), np.zeros((GRID, GRID))], -1).reshape(-1, 3)
    xy = rng.uniform(0.03, 0.07, size=(places, 2))
    pts, tip, force, step, seq, loc = [], [], [], [], [], []
    for s in range(places * repeats):
        where = xy[s % places]
        for t in range(steps + 1):
            depth = t * 1e-3
            pts.append(dent(rest, where, depth))
            tip.append([*where, -depth])
            force.append(0.5 * t)
            step.append(t)
            seq.append(s)
            loc.append(s % places)
    step_a, seq_a = np.array(step), np.array(seq)
    single, multi = example_pairs(step_a, seq_a, np.random.default_rng(seed))
    arrays = {
        "states/points": np.array(pts, np.float32),
        "states/valid": np.ones((len(pts), GRID * GRID), bool),
        "states/tip": np.array(tip, np.float32), "states/force": np.array(force, np.float32),
        "states/step": step_a, "states/sequence": seq_a, "states/location": np.array(loc),
        "states/session": np.zeros(len(pts), int),
        "single/start": single[:, 0], "single/end": single[:, 1],
        "multi/start": multi[:, 0], "multi/end": multi[:, 1],
    }
    attrs = {"provenance": "{}", "source": "lab", "units_length": "m", "units_force": "N",
             "step_n": 0.5, "frame": "phantom", "session_names": json.dumps(["dent"]),
             "point_names": json.dumps(DENT_NAMES)}
    write_h5(path, STATES, arrays, attrs)
    return arrays


def write_dent_split(data: Path, splits: Path, ratio: tuple[int, int, int] = (2, 1, 1),
                     folds: int = 2) -> None:
    """A fold manifest of a dent states file, grouped by place (seed 0)."""
    write_manifest(splits, build_manifest(data, default_plan(data, None, ratio, folds, 0)))


def dent_fold(d: Path, folds: int = 2) -> tuple[Path, Path]:
    """``d/states.h5`` of the dent model with its manifest ``d/splits.json``."""
    data, splits = d / "states.h5", d / "splits.json"
    write_dent_states(data)
    write_dent_split(data, splits, folds=folds)
    return data, splits

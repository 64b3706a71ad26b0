"""The simulate recording: a few MSM sequences, the surface at every force step.

What a person checks after simulate: does the surface dent where the force is applied, along
the force, by a plausible amount, and smoothly from step to step. Timeline ``force_step``
(sequence: t = 0 rest .. steps). Per logged sequence ``s``:

- ``msm/seq_<s>/surface``: Mesh3D of the surface (the spring triangles), vertices coloured by
  displacement from rest (dark blue 0 .. yellow at the sequence's largest displacement);
- ``msm/seq_<s>/loaded``: Points3D, the loaded mass;
- ``msm/seq_<s>/force``: Arrows3D ending at the loaded mass, along the force, 3 mm per N;
- ``plots/seq_<s>/{tip_displacement_mm,force_N}``: Scalars over the force steps.

Only a few sequences are logged (not all 1100): the view is for checking, the file is the data.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from core.recording import recording

APP_ID = "phantom-simulate"
ARROW_M_PER_N = 0.003
# viridis at 0, 0.25, 0.5, 0.75, 1
_STOPS = np.array([[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]],
                  dtype=float)


def blueprint(sequences: list[int]) -> rrb.Blueprint:
    """One 3D view per logged sequence, and the tip displacement and force curves."""
    views = [rrb.Spatial3DView(name=f"sequence {s}", origin=f"/msm/seq_{s:04d}")
             for s in sequences]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Grid(*views),
            rrb.TimeSeriesView(name="tip displacement (mm) and force (N)", origin="/plots"),
            column_shares=[3, 2],
        ),
        collapse_panels=False,
    )


def pick_sequences(n_sequences: int, count: int) -> list[int]:
    """``count`` sequence indices spread over the file (first and last included)."""
    count = max(0, min(count, n_sequences))
    return sorted({int(round(v)) for v in np.linspace(0, n_sequences - 1, count)}) if count else []


def write_simulate_recording(path: str | Path, arrays: dict[str, np.ndarray],
                             triangles: np.ndarray, count: int = 4) -> list[int]:
    """Save the recording of ``count`` sequences of a states file's arrays; returns them."""
    seq_of_state = arrays["states/sequence"]
    present = np.unique(seq_of_state)
    chosen = [int(present[i]) for i in pick_sequences(len(present), count)]
    with recording(APP_ID, path, blueprint(chosen)) as rec:
        for s in chosen:
            rows = np.flatnonzero(seq_of_state == s)
            rows = rows[np.argsort(arrays["states/step"][rows], kind="stable")]
            log_sequence(rec, s, arrays, rows, triangles)
    return chosen


def log_sequence(rec: rr.RecordingStream, s: int, arrays: dict[str, np.ndarray],
                 rows: np.ndarray, triangles: np.ndarray) -> None:
    """Log one sequence's states (``rows`` of the states arrays, in step order)."""
    points = arrays["states/points"][rows].astype(np.float64)
    tip = arrays["states/tip"][rows].astype(np.float64)
    fvec = arrays["states/force_vector"][rows].astype(np.float64)
    steps = arrays["states/step"][rows]
    disp = np.linalg.norm(points - points[0], axis=2)
    scale = max(float(disp.max()), 1e-12)
    root = f"msm/seq_{s:04d}"
    for k, t in enumerate(steps):
        rec.set_time("force_step", sequence=int(t))
        rec.log(f"{root}/surface", rr.Mesh3D(vertex_positions=points[k],
                                              triangle_indices=triangles,
                                              vertex_colors=colormap(disp[k] / scale)))
        rec.log(f"{root}/loaded", rr.Points3D(tip[k], radii=0.0012, colors=(230, 40, 40)))
        arrow = fvec[k] * ARROW_M_PER_N
        rec.log(f"{root}/force", rr.Arrows3D(origins=tip[k] - arrow, vectors=arrow,
                                              colors=(230, 40, 40), radii=0.0006))
    times = rr.TimeColumn("force_step", sequence=steps.astype(np.int64))
    tip_mm = np.linalg.norm(tip - tip[0], axis=1) * 1e3
    rec.send_columns(f"plots/seq_{s:04d}/tip_displacement_mm", indexes=[times],
                     columns=rr.Scalars.columns(scalars=tip_mm))
    rec.send_columns(f"plots/seq_{s:04d}/force_N", indexes=[times],
                     columns=rr.Scalars.columns(scalars=np.linalg.norm(fvec, axis=1)))


def colormap(v: np.ndarray) -> np.ndarray:
    """Viridis-like RGB (uint8) of values in [0, 1]."""
    v = np.clip(np.nan_to_num(v), 0.0, 1.0) * (len(_STOPS) - 1)
    lo = np.minimum(v.astype(int), len(_STOPS) - 2)
    frac = (v - lo)[:, None]
    return (_STOPS[lo] * (1 - frac) + _STOPS[lo + 1] * frac).round().astype(np.uint8)

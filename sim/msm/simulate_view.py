"""The simulate recording: a few MSM sequences, the surface at every force step.

What a person checks after simulate: does the surface dent where the force is applied, along
the force, by a plausible amount, and smoothly from step to step. One timeline, ``force_step``
(t = 0 rest .. steps; the applied force is t x the file's ``step_n``, the same in every
sequence, so it is written in the plot's name rather than drawn four times). Per logged
sequence ``s``:

- ``msm/seq_<s>/surface``: Mesh3D of the surface (the spring triangles), vertices coloured by
  displacement from rest, viridis on a square-root scale from 0 (purple) to the largest
  displacement of all logged sequences (yellow; a point load makes a narrow spike, which a
  linear scale would show as one yellow dot on a purple sheet), that range in the view's name;
- ``msm/seq_<s>/loaded``: Points3D, the loaded mass; ``msm/seq_<s>/force``: Arrows3D ending at
  it, along the force, 3 mm per N;
- ``plots/seq_<s>``: the loaded mass's displacement (mm) over the force steps, one colour per
  sequence, the same colour as the sequence's arrow;
- ``msm/seq_<s>/mould`` (a prior's moulds only): the cap at rest, a translucent grey Mesh3D
  under the markers, so a curved phantom reads as one.

Only a few sequences are logged (not all 1100): the view is for checking, the file is the data.
Everything is sent as columns, so the recording has no log_time timeline to choose by mistake.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from core.recording import colormap, declare_up, phantom_view, plot, recording

RestSurface = Callable[[int], tuple[np.ndarray, np.ndarray]]
APP_ID = "phantom-simulate"
MOULD_RGBA = (200, 200, 200, 90)       # a mould's cap at rest: translucent grey
TIMELINE = "force_step"
ARROW_M_PER_N = 0.003
# one colour per logged sequence (tab10), for its arrow, its loaded mass and its curve
SEQUENCE_COLORS = [(214, 39, 40), (31, 119, 180), (255, 127, 14), (148, 103, 189),
                   (44, 160, 44), (140, 86, 75), (227, 119, 194), (23, 190, 207)]


def blueprint(sequences: list[int], largest_mm: float, step_n: float, size: float,
              middle: np.ndarray | None = None) -> rrb.Blueprint:
    """One 3D view per logged sequence framing the surface (``size`` wide about ``middle``,
    default the grid's centre); the displacement curves."""
    xy = np.array([size / 2, size / 2]) if middle is None else middle
    centre = np.array([xy[0], xy[1], -size * 0.05])
    views = [phantom_view(f"sequence {s}: displacement 0 .. {largest_mm:.1f} mm (sqrt)",
                          [f"+ /msm/seq_{s:04d}/**"], centre, size) for s in sequences]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Grid(*views),
            plot(f"loaded mass displacement [mm] (force {step_n:g} N per step)",
                 "/plots"),
            column_shares=[3, 2],
        ),
        collapse_panels=False,
    )


def pick_sequences(n_sequences: int, count: int) -> list[int]:
    """``count`` sequence indices spread over the file (first and last included)."""
    count = max(0, min(count, n_sequences))
    return sorted({int(round(v)) for v in np.linspace(0, n_sequences - 1, count)}) if count else []


def write_simulate_recording(path: str | Path, arrays: dict[str, np.ndarray], step_n: float,
                             triangles: np.ndarray | None, footprint: tuple[float, float],
                             count: int = 4, rest_surface: RestSurface | None = None
                             ) -> list[int]:
    """Save the recording of ``count`` sequences of a states file's arrays (its force step
    ``step_n``, N) on the MSM's surface ``footprint`` (L, W) m; returns them. ``triangles``
    None: the states are points sampled at a lab's layout, drawn as points. ``rest_surface``:
    a sequence's surface at rest (vertices, triangles), drawn under its points."""
    seq_of_state = arrays["states/sequence"]
    present = np.unique(seq_of_state)
    chosen = [int(present[i]) for i in pick_sequences(len(present), count)]
    rows = {s: _rows(arrays, s) for s in chosen}
    largest = max((np.nanmax(_displacement(arrays, r), initial=0.0) for r in rows.values()),
                  default=0.0)
    empty = len(arrays["states/step"]) == 0
    first = np.array([[0.0, 0.0], footprint]) if empty else \
        arrays["states/points"][[rows[s][0] for s in chosen]].reshape(-1, 3)[:, :2]
    first = first[np.isfinite(first).all(axis=1)]          # a prior's padding: no point
    size = float(np.ptp(first, axis=0).max())
    middle = (first.min(axis=0) + first.max(axis=0)) / 2
    bp = blueprint(chosen, largest * 1e3, step_n, size, middle)
    with recording(APP_ID, path, bp) as rec:
        declare_up(rec)
        for i, s in enumerate(chosen):
            log_sequence(rec, s, arrays, rows[s], triangles, largest,
                         SEQUENCE_COLORS[i % len(SEQUENCE_COLORS)])
            if rest_surface is not None:
                vertices, faces = rest_surface(s)
                rec.log(f"msm/seq_{s:04d}/mould", rr.Mesh3D(
                    vertex_positions=vertices, triangle_indices=faces,
                    albedo_factor=MOULD_RGBA), static=True)
    return chosen


def _rows(arrays: dict[str, np.ndarray], s: int) -> np.ndarray:
    """The states of sequence ``s`` in step order."""
    rows = np.flatnonzero(arrays["states/sequence"] == s)
    return rows[np.argsort(arrays["states/step"][rows], kind="stable")]


def _displacement(arrays: dict[str, np.ndarray], rows: np.ndarray) -> np.ndarray:
    """(T, N) distance of every mass from its rest position (the sequence's step 0), m."""
    points = arrays["states/points"][rows].astype(np.float64)
    return np.linalg.norm(points - points[0], axis=2)


def log_sequence(rec: rr.RecordingStream, s: int, arrays: dict[str, np.ndarray],
                 rows: np.ndarray, triangles: np.ndarray | None, largest: float,
                 color: tuple[int, int, int]) -> None:
    """Log one sequence's states (``rows`` of the states arrays, in step order)."""
    points = arrays["states/points"][rows].astype(np.float64)
    tip = arrays["states/tip"][rows].astype(np.float64)
    arrow = arrays["states/force_vector"][rows].astype(np.float64) * ARROW_M_PER_N
    times = [rr.TimeColumn(TIMELINE, sequence=arrays["states/step"][rows].astype(np.int64))]
    colors = colormap(np.sqrt(_displacement(arrays, rows) / max(largest, 1e-12)))
    root, n, t = f"msm/seq_{s:04d}", points.shape[1], len(rows)
    if triangles is None:             # sampled at markers: points (those present), not a mesh
        seen = np.isfinite(points).all(axis=2)
        rec.log(f"{root}/surface", rr.Points3D.from_fields(radii=[0.002]), static=True)
        rec.send_columns(f"{root}/surface", indexes=times, columns=rr.Points3D.columns(
            positions=points[seen], colors=colors[seen]).partition(seen.sum(axis=1)))
    else:
        rec.log(f"{root}/surface", rr.Mesh3D.from_fields(triangle_indices=triangles),
                static=True)
        rec.send_columns(f"{root}/surface", indexes=times, columns=rr.Mesh3D.columns(
            vertex_positions=points.reshape(-1, 3), vertex_colors=colors.reshape(-1, 3))
            .partition(np.full(t, n)))
    rec.log(f"{root}/loaded", rr.Points3D.from_fields(radii=[0.0015], colors=[color]),
            static=True)
    rec.send_columns(f"{root}/loaded", indexes=times,
                     columns=rr.Points3D.columns(positions=tip))
    rec.log(f"{root}/force", rr.Arrows3D.from_fields(radii=[0.0006], colors=[color]),
            static=True)
    rec.send_columns(f"{root}/force", indexes=times,
                     columns=rr.Arrows3D.columns(origins=tip - arrow, vectors=arrow))
    rec.log(f"plots/seq_{s:04d}", rr.SeriesLines(names=[f"sequence {s}"], colors=[color],
                                                 widths=[2.0]), static=True)
    rec.send_columns(f"plots/seq_{s:04d}", indexes=times, columns=rr.Scalars.columns(
        scalars=np.linalg.norm(tip - tip[0], axis=1) * 1e3))

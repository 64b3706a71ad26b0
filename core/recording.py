"""Rerun recordings of each stage: opened beside the output, written atomically, read back.

Each stage's view logs what a person checks at that stage (docs/recordings.md); this
module only handles where the recording goes and how tests and `pipeline inspect` read it
back.
"""

from __future__ import annotations

import contextlib
import itertools
import os
from collections.abc import Iterator
from contextlib import AbstractContextManager
from pathlib import Path
from typing import overload

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from core.atomic import atomic_output


def default_rrd_path(output: str | Path, folder: bool | None = None) -> Path:
    """Where a stage puts its recording when ``--rrd`` is not given.

    Beside an output file, with its suffix replaced by ``.rrd`` (``x.mcap`` -> ``x.rrd``) or,
    when it has none or is itself ``.rrd``, added (``x`` -> ``x.rrd``), so the two never
    collide; inside an output folder as ``recording.rrd``. ``folder`` says which ``output`` is;
    None: a folder when one exists there.
    """
    out = Path(output)
    if folder is None:
        folder = out.is_dir()
    if folder:
        return out / "recording.rrd"
    if out.suffix and out.suffix != ".rrd":
        return out.with_suffix(".rrd")
    return out.with_name(out.name + ".rrd")


_SERIAL = itertools.count()   # a process (a demo worker) writes many recordings: each its own id


@overload
def recording(app_id: str, path: str | Path, blueprint: rrb.BlueprintLike | None = None
              ) -> AbstractContextManager[rr.RecordingStream]: ...


@overload
def recording(app_id: str, path: None, blueprint: rrb.BlueprintLike | None = None
              ) -> AbstractContextManager[None]: ...


@overload
def recording(app_id: str, path: str | Path | None, blueprint: rrb.BlueprintLike | None = None
              ) -> AbstractContextManager[rr.RecordingStream | None]: ...


def recording(app_id: str, path: str | Path | None, blueprint: rrb.BlueprintLike | None = None
              ) -> AbstractContextManager[rr.RecordingStream | None]:
    """A recording stream saved to ``path`` (atomically), or ``None`` when ``path`` is None.

    Stage code does ``with recording(...) as rec: if rec: log_...(rec, ...)``; with a path
    given, the stream is always there.
    """
    return _stream(app_id, path, blueprint)


@contextlib.contextmanager
def _stream(app_id: str, path: str | Path | None, blueprint: rrb.BlueprintLike | None
            ) -> Iterator[rr.RecordingStream | None]:
    """:func:`recording`'s work."""
    if path is None:
        yield None
        return
    with atomic_output(path) as tmp:
        rec = rr.RecordingStream(app_id, recording_id=f"{app_id}-{os.getpid()}-{next(_SERIAL)}")
        rec.save(tmp, default_blueprint=blueprint)
        try:
            yield rec
        finally:
            rec.flush()
            rec.disconnect()


def time_column(name: str, time_ns: np.ndarray) -> rr.TimeColumn:
    """An int64-nanosecond time column for ``send_columns`` (a duration since the device start)."""
    ns = np.asarray(time_ns, dtype=np.int64).astype("timedelta64[ns]")
    return rr.TimeColumn(name, duration=ns)


def rrd_entities(path: str | Path) -> dict[str, set[str]]:
    """Entity paths in a recording, each with its archetype names (``Points3D``, ``Scalars``)."""
    from rerun.chunk import RrdReader

    found: dict[str, set[str]] = {}
    for col in RrdReader(str(path)).store().schema().component_columns():
        archetype = (col.archetype or "").rsplit(".", 1)[-1]
        found.setdefault(col.entity_path, set()).add(archetype)
    return found


def rrd_timelines(path: str | Path) -> set[str]:
    """The timelines of a recording (a person should not have to choose among useless ones)."""
    from rerun.chunk import RrdReader

    return {c.name for c in RrdReader(str(path)).store().schema().index_columns()}


def rrd_has_blueprint(path: str | Path) -> bool:
    """Whether the recording carries a default blueprint (the layout a person opens)."""
    from rerun.chunk import RrdReader

    return bool(RrdReader(str(path)).blueprints())


# --- what every stage's views share: up axis, a camera on the phantom, named series, colours

UP = rr.ViewCoordinates.RIGHT_HAND_Z_UP
# viridis at 0, 0.25, 0.5, 0.75, 1: dark purple (none) .. yellow (most)
_VIRIDIS = np.array([[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98],
                     [253, 231, 37]], dtype=float)


def declare_up(rec: rr.RecordingStream, path: str = "/") -> None:
    """Say that +z is up (the phantom frame's normal; QTM's lab frame), so 3D views start
    upright."""
    rec.log(path, UP, static=True)


def phantom_eye(centre: np.ndarray, size: float, up: np.ndarray | None = None
                ) -> rrb.EyeControls3D:
    """A camera in front of and above a phantom of side ``size`` (m) centred at ``centre``,
    looking down at it at about 45 degrees, so it fills the view without a horizon."""
    up = np.array([0.0, 0.0, 1.0]) if up is None else np.asarray(up, float)
    front = np.cross(up, [1.0, 0.0, 0.0])
    front = front / (np.linalg.norm(front) or 1.0)
    c = np.asarray(centre, float)
    return rrb.EyeControls3D(kind=rrb.Eye3DKind.Orbital, position=c - 1.0 * size * front
                             + 1.1 * size * up, look_target=c, eye_up=up)


def phantom_view(name: str, contents: list[str], centre: np.ndarray, size: float,
                 up: np.ndarray | None = None, origin: str = "/") -> rrb.Spatial3DView:
    """A 3D view framing the phantom, grid off (it drew a horizon across the view)."""
    return rrb.Spatial3DView(name=name, origin=origin, contents=contents,
                             eye_controls=phantom_eye(centre, size, up),
                             line_grid=rrb.LineGrid3D(visible=False))


MOULD_RGBA = (200, 200, 210, 90)     # a curved phantom's mould: light grey, translucent


def log_mould(rec: rr.RecordingStream, path: str, vertices: np.ndarray, faces: np.ndarray,
              to: np.ndarray | None = None) -> None:
    """A curved phantom's mould (its triangles, ``vertices`` (V, 3) moved by the 4 x 4 ``to``
    when given) at ``path``, static: the surface its markers rest on."""
    if to is not None:
        vertices = vertices @ to[:3, :3].T + to[:3, 3]
    rec.log(path, rr.Mesh3D(vertex_positions=vertices, triangle_indices=faces,
                            albedo_factor=MOULD_RGBA), static=True)


def plot(name: str, origin: str, y_range: tuple[float, float] | None = None,
         legend: bool = True) -> rrb.TimeSeriesView:
    """A time-series view of one quantity (its unit in ``name``), legend in the top-left
    corner (data rise to the right), y fixed to ``y_range`` when given."""
    return rrb.TimeSeriesView(
        name=name, origin=origin,
        axis_y=rrb.ScalarAxis(range=y_range, zoom_lock=False) if y_range else None,
        plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.LeftTop, visible=legend))


def send_series(rec: rr.RecordingStream, path: str, timeline: str, time_ns: np.ndarray,
                values: np.ndarray, name: str, color: tuple[int, ...], width: float = 1.5
                ) -> None:
    """One named, coloured line of scalars over a duration timeline (int64 ns)."""
    rec.log(path, rr.SeriesLines(names=[name], colors=[color], widths=[width]), static=True)
    rec.send_columns(path, indexes=[time_column(timeline, time_ns)],
                     columns=rr.Scalars.columns(scalars=np.asarray(values, np.float64)))


def colormap(v: np.ndarray) -> np.ndarray:
    """Viridis RGB (uint8) of values in [0, 1] (NaN as 0): for errors and displacements,
    with the range the colours span written in the view's name."""
    v = np.clip(np.nan_to_num(np.asarray(v, float)), 0.0, 1.0) * (len(_VIRIDIS) - 1)
    lo = np.minimum(v.astype(int), len(_VIRIDIS) - 2)
    frac = (v - lo)[..., None]
    return (_VIRIDIS[lo] * (1 - frac) + _VIRIDIS[lo + 1] * frac).round().astype(np.uint8)

"""Rerun recordings of each stage: opened beside the output, written atomically, read back.

Each stage logs what a person checks at that stage (see DESIGN.md); this module only handles
where the recording goes and how tests and `pipeline inspect` read it back.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

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


@contextlib.contextmanager
def recording(
    app_id: str, path: str | Path | None, blueprint: rrb.BlueprintLike | None = None
) -> Iterator[rr.RecordingStream | None]:
    """A recording stream saved to ``path`` (atomically), or ``None`` when ``path`` is None.

    Stage code does ``with recording(...) as rec: if rec: log_...(rec, ...)``.
    """
    if path is None:
        yield None
        return
    with atomic_output(path) as tmp:
        rec = rr.RecordingStream(app_id, recording_id=f"{app_id}-{os.getpid()}")
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


def rrd_has_blueprint(path: str | Path) -> bool:
    """Whether the recording carries a default blueprint (the layout a person opens)."""
    from rerun.chunk import RrdReader

    return bool(RrdReader(str(path)).blueprints())

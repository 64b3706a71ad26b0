"""The live recording: what the operator watches while pressing, and keeps beside the MCAP.

One timeline, ``mocap_time`` (since the first frame received); +z up. Entities:

* ``scene/phantom`` (blue) and ``scene/cluster`` (orange): the session's markers, at most
  :data:`VIEW_HZ` times a second (what a person can see), lost ones left out;
  ``scene/tip`` (red ball) once the tip is calibrated;
* ``force/magnitude``: the tared force magnitude (N) at the mocap rate, sent a frame's samples
  at a time (``send_columns``: the 1 kHz board never floods the viewer);
* ``quality/lost``: markers of the session lost (logged where the count changes);
  ``quality/saturated`` and ``quality/over_range``: 1 while a gauge sits on the amplifier's
  rail or the force is beyond the sensor's rating (logged where they change), as it happens;
* ``status``: a TextLog of the session: connected, calibrated, the end and its reason.

The recording goes to a file (always) and, on request, to a viewer spawned beside it
(``--spawn``) or served to a browser (``--serve``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from core.recording import declare_up, time_column

APP_ID = "phantom-live"
TIMELINE = "mocap_time"
VIEW_HZ = 30.0
RADIUS_M = 0.0015
COLORS = {"phantom": (60, 140, 230), "cluster": (245, 140, 30), "tip": (230, 30, 30),
          "force": (40, 170, 80), "lost": (150, 150, 150), "saturated": (230, 30, 30),
          "over_range": (140, 0, 140)}


def blueprint() -> rrb.Blueprint:
    """The scene beside the force and the quality plots."""
    return rrb.Blueprint(rrb.Horizontal(
        rrb.Spatial3DView(origin="scene", name="markers and tip"),
        rrb.Vertical(rrb.TimeSeriesView(origin="force", name="force (N)"),
                     rrb.TimeSeriesView(origin="quality", name="lost markers, flags")),
        column_shares=[3, 2]))


class LiveView:
    """The live recording stream (file, and viewer where asked)."""

    def __init__(self, path: Path, phantom: int, spawn: bool = False,
                 serve: bool = False) -> None:
        self.rec = rr.RecordingStream(APP_ID)
        sinks: list = [rr.FileSink(str(path))]
        if spawn:
            rr.spawn(connect=False)
            sinks.append(rr.GrpcSink())
        if serve:
            sinks.append(rr.GrpcServerSink())
        self.rec.set_sinks(*sinks, default_blueprint=blueprint())
        if serve:
            rr.serve_web_viewer(open_browser=False)
        self.phantom = phantom
        self._next_scene = 0
        self._last: dict[str, float] = {}
        declare_up(self.rec, "scene")
        for name, color in COLORS.items():
            if name in ("force", "lost", "saturated", "over_range"):
                where = "force/magnitude" if name == "force" else f"quality/{name}"
                self.rec.log(where, rr.SeriesLines(colors=[color], names=[name]), static=True)

    def due(self, time_ns: int) -> bool:
        """Whether the scene is drawn at this frame: at most :data:`VIEW_HZ` times a second."""
        return time_ns >= self._next_scene

    def frame(self, time_ns: int, markers: np.ndarray, tip: np.ndarray | None) -> None:
        """One frame's session markers (M, 3) m (phantom first, then the cluster) and, when
        :meth:`due`, its tip: the lost count where it changed, the scene when due."""
        lost = np.isnan(markers).any(axis=1)
        self._changed("quality/lost", time_ns, float(lost.sum()))
        if not self.due(time_ns):
            return
        self._next_scene = time_ns + int(1e9 / VIEW_HZ)
        self._at(time_ns)
        seen = ~lost
        for name, part in (("phantom", slice(0, self.phantom)),
                           ("cluster", slice(self.phantom, None))):
            pts = markers[part][seen[part]]
            self.rec.log(f"scene/{name}", rr.Points3D(pts, radii=RADIUS_M,
                                                      colors=COLORS[name]))
        if tip is not None and np.isfinite(tip).all():
            self.rec.log("scene/tip", rr.Points3D([tip], radii=2 * RADIUS_M,
                                                  colors=COLORS["tip"]))

    def force(self, time_ns: np.ndarray, magnitude: np.ndarray, saturated: np.ndarray,
              over_range: np.ndarray) -> None:
        """A frame's force samples, magnitude (N) in one batch; the flags where they
        changed (a step plot: 1 while on the rail or beyond the rating)."""
        self.rec.send_columns("force/magnitude", indexes=[time_column(TIMELINE, time_ns)],
                              columns=rr.Scalars.columns(scalars=magnitude))
        for name, flag in (("saturated", saturated), ("over_range", over_range)):
            self._changed(f"quality/{name}", int(time_ns[-1]), float(flag.any()))

    def _changed(self, path: str, time_ns: int, value: float) -> None:
        """Log ``value`` at ``path`` where it differs from the last logged."""
        if self._last.get(path) == value:
            return
        self._last[path] = value
        self._at(time_ns)
        self.rec.log(path, rr.Scalars(value))

    def _at(self, time_ns: int) -> None:
        self.rec.set_time(TIMELINE, duration=np.timedelta64(int(time_ns), "ns"))

    def note(self, time_ns: int, text: str, level: str = rr.TextLogLevel.INFO) -> None:
        """A line of the session's status."""
        self._at(time_ns)
        self.rec.log("status", rr.TextLog(text, level=level))

    def close(self) -> None:
        self.rec.flush()
        self.rec.disconnect()

"""The live recording: what the operator watches while pressing, and keeps beside the MCAP.

One timeline, ``mocap_time`` (since the first frame received); +z up. Entities:

* ``scene/phantom`` (blue) and ``scene/cluster`` (orange): the session's markers, at most
  :data:`VIEW_HZ` times a second (what a person can see), lost ones left out, framed on the
  phantom once it is seen; ``scene/tip`` (red ball); a curved phantom's ``scene/shape``
  (its mould where the markers registered it); ``scene/coverage``: a ball per location
  pressed (at its first press's tip), coloured by the highest force level reached there
  (viridis, 0 to :data:`COVERAGE_N` N) and labelled "location: presses x, top level", updated
  as each press ends;
* ``force/magnitude``: the tared force magnitude (N) at the mocap rate, sent a frame's samples
  at a time (``send_columns``: the 1 kHz board never floods the viewer);
* ``quality/lost``: the most markers of the session lost in a frame since the last drawing;
  ``quality/saturated`` and ``quality/over_range``: 1 where a gauge sat on the amplifier's
  rail or the force went beyond the sensor's rating since the last drawing;
* with ``--model``: ``scene/model`` (green), the model's surface for the tip now (region
  mode), and ``model/ld_mm``, ``model/force_error_n``: its L_d against the markers measured
  and its force error, as each press goes on; its envelope warnings in ``status``;
* ``status``: a TextLog of the session: connected, calibrated, each press as it ends (its
  location, peak, the levels reached there), the end and its reason.

The recording goes to a file (always) and, on request, to a viewer spawned beside it
(``--spawn``) or served to a browser (``--serve``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from core.recording import colormap, declare_up, log_mould, phantom_view, plot, time_column
from data_schema.shape import Shape
from live.session.model import Reading
from live.session.presses import PressDone
from live.session.states import LivePress, OnlineStates, coverage

APP_ID = "phantom-live"
TIMELINE = "mocap_time"
VIEW_HZ = 30.0
COVERAGE_N = 7.5               # the coverage's colours span 0 to this level (the MSM's top)
RADIUS_M = 0.0015
COLORS = {"phantom": (60, 140, 230), "cluster": (245, 140, 30), "tip": (230, 30, 30),
          "force": (40, 170, 80), "lost": (150, 150, 150), "saturated": (230, 30, 30),
          "model": (90, 220, 120), "ld_mm": (90, 220, 120), "force_error_n": (230, 200, 60),
          "over_range": (140, 0, 140)}


def blueprint(centre: np.ndarray | None = None, size: float = 0.1,
              model: bool = False) -> rrb.Blueprint:
    """The scene beside the force and the quality plots (and the model's, with one); the
    scene framed on the phantom and the indenter (``centre``, ``size`` m) once both are
    seen."""
    name = "markers (phantom blue, cluster orange), tip red" + \
        (", model green" if model else "")
    scene = rrb.Spatial3DView(origin="scene", name=name) if centre is None else \
        phantom_view(name, ["$origin/**"], centre, size, origin="scene")
    plots: list[rrb.View] = [plot("force (N)", "force"),
                             plot("lost markers, saturated, over range", "quality")]
    if model:
        plots.append(plot("model: L_d (mm), force error (N)", "model"))
    plots.append(rrb.TextLogView(origin="status", name="status: presses, their states, warnings"))
    return rrb.Blueprint(rrb.Horizontal(scene, rrb.Vertical(*plots), column_shares=[3, 2]))


class LiveView:
    """The live recording stream (file, and viewer where asked)."""

    def __init__(self, path: Path, phantom: int, spawn: bool = False,
                 serve: bool = False, model: bool = False) -> None:
        self.rec = rr.RecordingStream(APP_ID)
        sinks: list = [rr.FileSink(str(path))]
        if spawn:
            rr.spawn(connect=False)
            sinks.append(rr.GrpcSink())
        if serve:
            sinks.append(rr.GrpcServerSink())
        self.rec.set_sinks(*sinks, default_blueprint=blueprint(model=model))
        self.with_model = model
        if serve:
            rr.serve_web_viewer(open_browser=False)
        self.phantom = phantom
        self._next_scene = 0
        self._flags = {"lost": 0.0, "saturated": 0.0, "over_range": 0.0}
        self._framed = False
        self._warned: set[str] = set()
        declare_up(self.rec, "scene")
        for name, color in COLORS.items():
            if name in ("force", "lost", "saturated", "over_range", "ld_mm", "force_error_n"):
                where = {"force": "force/magnitude", "ld_mm": "model/ld_mm",
                         "force_error_n": "model/force_error_n"}.get(name, f"quality/{name}")
                self.rec.log(where, rr.SeriesLines(colors=[color], names=[name]), static=True)

    def due(self, time_ns: int) -> bool:
        """Whether the scene is drawn at this frame: at most :data:`VIEW_HZ` times a second."""
        return time_ns >= self._next_scene

    def frame(self, time_ns: int, markers: np.ndarray, tip: np.ndarray | None) -> None:
        """One frame's session markers (M, 3) m (phantom first, then the cluster) and, when
        :meth:`due`, its tip; drawn with the quality plots when due."""
        lost = np.isnan(markers).any(axis=1)
        self._flags["lost"] = max(self._flags["lost"], float(lost.sum()))
        if not self.due(time_ns):
            return
        self._next_scene = time_ns + int(1e9 / VIEW_HZ)
        self._at(time_ns)
        seen = ~lost
        if not self._framed and seen[:self.phantom].sum() >= 3 and seen[self.phantom:].any():
            self._frame_scene(markers[seen])
        for name, part in (("phantom", slice(0, self.phantom)),
                           ("cluster", slice(self.phantom, None))):
            pts = markers[part][seen[part]]
            self.rec.log(f"scene/{name}", rr.Points3D(pts, radii=RADIUS_M,
                                                      colors=COLORS[name]))
        if tip is not None and np.isfinite(tip).all():
            self.rec.log("scene/tip", rr.Points3D([tip], radii=2 * RADIUS_M,
                                                  colors=COLORS["tip"]))
        for name, value in self._flags.items():   # the worst since the last drawing
            self.rec.log(f"quality/{name}", rr.Scalars(value))
            self._flags[name] = 0.0

    def force(self, time_ns: np.ndarray, magnitude: np.ndarray, saturated: np.ndarray,
              over_range: np.ndarray) -> None:
        """A frame's force samples, magnitude (N) in one batch; the flags kept for the next
        drawing (1 if any sample since the last was on the rail, or beyond the rating)."""
        self.rec.send_columns("force/magnitude", indexes=[time_column(TIMELINE, time_ns)],
                              columns=rr.Scalars.columns(scalars=magnitude))
        self._flags["saturated"] = max(self._flags["saturated"], float(saturated.any()))
        self._flags["over_range"] = max(self._flags["over_range"], float(over_range.any()))

    def _frame_scene(self, seen: np.ndarray) -> None:
        """Frame the scene on the phantom and the indenter together (the box round every
        marker seen, once, at the first frame that shows both): the tip pressing and the
        cluster above it stay in view."""
        self._framed = True
        lo, hi = seen.min(axis=0), seen.max(axis=0)
        size = float((hi - lo).max()) or 0.1
        self.rec.send_blueprint(blueprint((lo + hi) / 2, size, self.with_model))

    def _at(self, time_ns: int) -> None:
        self.rec.set_time(TIMELINE, duration=np.timedelta64(int(time_ns), "ns"))

    def press(self, press: PressDone) -> None:
        """A press that ended: a status line."""
        self.note(press.end_ns, f"press {press.number} ended: peak {press.peak_n:.2f} N")

    def taken(self, time_ns: int, taken: LivePress, states: OnlineStates) -> None:
        """A press's states: a status line, and the coverage of every location (a ball at
        its presses' contact point, coloured by the highest level read there, labelled with
        its presses, top level and states)."""
        step = states.extract.step_n
        st = taken.states
        read = (f"{len(st.step)} states, levels {st.step.min() * step:g}-"
                f"{st.step.max() * step:g} N" if len(st.step) else "no states (its force "
                "was saturated or over range)" if taken.press.untrusted_force else "no states")
        self.note(time_ns, f"press {taken.number} at location {taken.location + 1}: {read}",
                  rr.TextLogLevel.INFO if len(st.step) else rr.TextLogLevel.WARN)
        places = coverage(states.taken)
        top = np.array([c.top_level(step) for c in places])
        self.rec.log("scene/coverage", rr.Points3D(
            [c.centre for c in places], radii=3 * RADIUS_M, colors=colormap(top / COVERAGE_N),
            labels=[f"{i + 1}: {c.presses} x, {c.states.sum()} states to {top[i]:g} N"
                    for i, c in enumerate(places)]))

    def model(self, time_ns: int, reading: Reading) -> None:
        """The model's surface for the tip now beside the markers, its L_d and force error,
        and its envelope warnings (each once a press)."""
        self._at(time_ns)
        self.rec.log("scene/model", rr.Points3D(reading.predicted, radii=RADIUS_M,
                                                colors=COLORS["model"]))
        self.rec.log("model/ld_mm", rr.Scalars(reading.ld_mm))
        self.rec.log("model/force_error_n", rr.Scalars(reading.force_error_n))
        for text in reading.warnings:
            if text not in self._warned:
                self._warned.add(text)
                self.rec.log("status", rr.TextLog(text, level=rr.TextLogLevel.WARN))

    def shape(self, shape: Shape, to_shape: np.ndarray) -> None:
        """A curved phantom's mould where its markers registered it (lab, translucent)."""
        log_mould(self.rec, "scene/shape", shape.vertices, shape.faces, np.linalg.inv(to_shape))

    def note(self, time_ns: int, text: str, level: rr.TextLogLevel = rr.TextLogLevel.INFO
             ) -> None:
        """A line of the session's status."""
        self._at(time_ns)
        self.rec.log("status", rr.TextLog(text, level=level))

    def warning(self, time_ns: int, text: str) -> None:
        """A line of the session's status that something went wrong."""
        self.note(time_ns, text, rr.TextLogLevel.WARN)

    def close(self) -> None:
        self.rec.flush()
        self.rec.disconnect()

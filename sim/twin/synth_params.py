"""Every setting of ``pipeline synth``.

The fields' defaults are the command line's: ``pipeline/synth_cmd.py`` reads them here. Those
the twin itself has take its defaults (:class:`~sim.twin.twin_scene.TwinParams`).
"""

from __future__ import annotations

from dataclasses import dataclass

from sim.twin.twin_scene import TwinParams

T = TwinParams


@dataclass(frozen=True)
class SynthParams:
    """Every setting of ``pipeline synth``: the session (:class:`TwinParams`' fields), the
    phantom's layout, and the press the recording shows."""

    seed: int = T.seed
    locations: int = T.locations
    repeats: int = T.repeats
    press_seconds: float | None = T.press_seconds   # None: about 6 s a press
    pivot_seconds: float = T.pivot_seconds
    trigger: bool = T.trigger
    offset_s: float | None = T.offset_s             # None: drawn
    drift_ppm: float | None = T.drift_ppm           # None: drawn
    force_via: str = T.force_via
    force_file: str | None = T.force_file           # None: the route's first
    rate_hz: float = T.rate_hz                      # the mocap's frame rate
    markers: str = "5x5"                            # RxC or scattered:N
    marker_pitch_mm: float = 20.0
    size: str = "100x100"                           # LxW mm
    view_press: int = 0                             # the press the recording shows

    def session_fields(self) -> dict[str, object]:
        """The fields :class:`TwinParams` takes as they are (all but the layout's and the
        recording's)."""
        return {k: getattr(self, k) for k in (
            "seed", "locations", "repeats", "press_seconds", "pivot_seconds", "trigger",
            "offset_s", "drift_ppm", "force_via", "force_file", "rate_hz")}

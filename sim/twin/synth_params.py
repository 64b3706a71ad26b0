"""Every setting of ``pipeline synth``.

The fields' defaults are the command line's: ``pipeline/synth_cmd.py`` reads them here. Those
the twin itself has take its defaults (:class:`~sim.twin.twin_scene.TwinParams`). The places
(``locations``), the inclusions and the layer are checked as the settings are made, against
the block's size, with the bounds the twin states (:mod:`sim.twin.twin_scene`,
:mod:`sim.twin.material_regions`): a library caller is refused as the command line is.
"""

from __future__ import annotations

from dataclasses import dataclass

from sim.twin.marker_layout import parse_size
from sim.twin.material_regions import (
    Inclusion,
    Layer,
    check_regions,
    parse_inclusion,
    parse_layer,
)
from sim.twin.phantom import PhantomSpec
from sim.twin.twin_scene import TwinParams, parse_locations, place_count

T = TwinParams


@dataclass(frozen=True)
class SynthParams:
    """Every setting of ``pipeline synth``: the session (:class:`TwinParams`' fields), the
    phantom's layout and its other silicones, and the press the recording shows."""

    seed: int = T.seed
    locations: int | str = T.locations              # N drawn at random, or a grid "RxC"
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
    inclusions: tuple[str, ...] = ()                # each "X,Y,DEPTH,RADIUS,RATIO" (mm)
    layer: str | None = None                        # "THICKNESS,RATIO" (mm)
    view_press: int = 0                             # the press the recording shows

    def __post_init__(self) -> None:
        parse_locations(self.locations)
        inclusions, layer = self.regions()
        check_regions(inclusions, layer, self.block_size())

    @property
    def places(self) -> int:
        """How many places are pressed."""
        return place_count(parse_locations(self.locations))

    def block_size(self) -> tuple[float, float, float]:
        """The block (L, W, thickness) in m: ``size`` and the twin's thickness."""
        return (*parse_size(self.size), PhantomSpec.size[2])

    def regions(self) -> tuple[tuple[Inclusion, ...], Layer | None]:
        """The inclusions and the layer, parsed."""
        return (tuple(parse_inclusion(t) for t in self.inclusions),
                None if self.layer is None else parse_layer(self.layer))

    def session_fields(self) -> dict[str, object]:
        """The fields :class:`TwinParams` takes (all but the layout's, the regions' and the
        recording's), the places parsed."""
        return {"locations": parse_locations(self.locations), **{k: getattr(self, k) for k in (
            "seed", "repeats", "press_seconds", "pivot_seconds", "trigger",
            "offset_s", "drift_ppm", "force_via", "force_file", "rate_hz")}}

"""Every setting of ``pipeline synth``, and its bounds.

The fields' defaults are the command line's: ``pipeline/synth_cmd.py`` reads them here, and
its option types the bounds (``BOUNDS``). Those the twin itself has take its defaults
(:class:`~sim.twin.twin_scene.TwinParams`; the markers, their pitch and the footprint:
:class:`~sim.twin.marker_layout.MarkerLayout` and :class:`~sim.twin.phantom.PhantomSpec`).
Every setting is checked as the settings are made (the places, the layout, the inclusions and
the layer against the block's size, with the bounds the twin states: :mod:`sim.twin.twin_scene`,
:mod:`sim.twin.marker_layout`, :mod:`sim.twin.material_regions`): a library caller is refused
as the command line is.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, ClassVar

from core.bounds import Bound, check_bounds
from sim.twin.marker_layout import (
    MIN_PITCH_M,
    PITCH_SPACINGS,
    MarkerLayout,
    layout_text,
    parse_layout,
    parse_size,
    size_text,
)
from sim.twin.material_regions import (
    Inclusion,
    Layer,
    check_regions,
    parse_inclusion,
    parse_layer,
)
from sim.twin.phantom import PhantomSpec
from sim.twin.twin_scene import (
    MAX_DRIFT_PPM,
    MAX_OFFSET_S,
    PIVOT_SECONDS,
    PLACES,
    PRESS_SECONDS,
    RATE_HZ,
    TwinParams,
    check_params,
    parse_locations,
    place_count,
)
from sim.twin.twin_shape import check_one_silicone, parse_shape

T = TwinParams
RANDOM_PLACES = Bound(1, 10, whole=True, why="places are drawn 15 mm apart: more rarely fit")


@dataclass(frozen=True)
class SynthParams:
    """Every setting of ``pipeline synth``: the session (:class:`TwinParams`' fields), the
    phantom's layout (the twin's own by default) and its other silicones, and the press the
    recording shows; bad input, in one line naming the setting, where one is out of its
    bounds or the session could not be."""

    seed: int = T.seed
    locations: int | str = PLACES                   # N drawn at random, or a grid "RxC"
    repeats: int = T.repeats
    press_seconds: float | None = T.press_seconds   # None: about 6 s a press
    pivot_seconds: float = T.pivot_seconds
    trigger: bool = T.trigger
    offset_s: float | None = T.offset_s             # None: drawn
    drift_ppm: float | None = T.drift_ppm           # None: drawn
    force_via: str = T.force_via
    force_file: str | None = T.force_file           # None: the route's first
    rate_hz: float = T.rate_hz                      # the mocap's frame rate
    markers: str = layout_text(MarkerLayout())      # RxC or scattered:N
    marker_pitch_mm: float = MarkerLayout.pitch * 1e3
    size: str = size_text(PhantomSpec.size)         # LxW mm
    inclusions: tuple[str, ...] = ()                # each "X,Y,DEPTH,RADIUS,RATIO" (mm)
    layer: str | None = None                        # "THICKNESS,RATIO" (mm)
    shape: str | None = None                        # "dome:HEIGHT" (mm) or a surface file
    view_press: int = 0                             # the press the recording shows

    BOUNDS: ClassVar[Mapping[str, Bound]] = MappingProxyType({
        "repeats": Bound(1, 50, whole=True),
        "press_seconds": Bound(*PRESS_SECONDS, unit="s"),
        "pivot_seconds": Bound(*PIVOT_SECONDS, unit="s"),
        "offset_s": Bound(-MAX_OFFSET_S, MAX_OFFSET_S, unit="s"),
        "drift_ppm": Bound(-MAX_DRIFT_PPM, MAX_DRIFT_PPM, unit="ppm"),
        "rate_hz": Bound(*RATE_HZ, unit="Hz"),
        "marker_pitch_mm": Bound(MIN_PITCH_M * 1e3, unit="mm",
                                 why=f"the lattice would be finer than "
                                     f"{MIN_PITCH_M / PITCH_SPACINGS * 1e3:g} mm"),
        "view_press": Bound(0, whole=True),
    })

    def __post_init__(self) -> None:
        check_bounds(self, self.BOUNDS)
        if isinstance(self.locations, int):
            RANDOM_PLACES.check("locations", self.locations)
        parse_locations(self.locations)
        parse_layout(self.markers, self.marker_pitch_mm, self.seed)
        check_params(TwinParams(**self.session_fields()))
        inclusions, layer = self.regions()
        check_regions(inclusions, layer, self.block_size())
        if self.shape is not None:
            parse_shape(self.shape, self.block_size())
        check_one_silicone(self.shape, inclusions, layer)

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

    def session_fields(self) -> dict[str, Any]:
        """The fields :class:`TwinParams` takes (all but the layout's, the regions' and the
        recording's), the places parsed."""
        return {"locations": parse_locations(self.locations), **{k: getattr(self, k) for k in (
            "seed", "repeats", "press_seconds", "pivot_seconds", "trigger",
            "offset_s", "drift_ppm", "force_via", "force_file", "rate_hz")}}

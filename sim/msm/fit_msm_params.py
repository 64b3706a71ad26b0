"""Every setting of ``pipeline fit-msm``, and the files it reads.

The fields' defaults are the command line's: ``pipeline/fit_msm_cmd.py`` reads them here.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import ClassVar

from core.bounds import Bound, check_bounds
from sim.msm import paper
from sim.msm.msm_fit import K_MAX, K_MIN
from sim.msm.msm_grid import SPACING
from sim.msm.msm_protocol import CONTACT_RADIUS
from sim.msm.msm_regions import parse_regions


@dataclass(frozen=True)
class FitMsmInputs:
    """The measured states, and optionally their fold manifest (fit on one fold's training
    presses only)."""

    states: Path
    splits: Path | None = None


@dataclass(frozen=True)
class FitMsmParams:
    """Every setting of ``pipeline fit-msm``; bad input, in one line naming the setting, where
    one is out of its bounds."""

    max_sequences: int | None = None    # sequences used (drawn with the seed when more);
                                        # None: UNIFORM_SEQUENCES, or every one for a map
    fold: int = 0                       # the fold of ``splits`` whose training presses fit
    start: tuple[float, float] = (paper.K_BETWEEN, paper.K_FIXED)   # N/m, the paper's
    contact_radius: float | None = None  # m; None: 0 for lab states, an MSM file's own
    spacing: float | None = None        # m between masses (lab states); None: the paper's
    workers: int = 0                    # processes; 0: the cores this process may use
    seed: int = 0
    map: bool = False                   # also fit a stiffness map (sim.msm.msm_map_fit)
    regions: tuple[int, int] | None = None   # the map's regions: rows (along y) x per row
                                             # (x); None: the finest the places cover

    UNIFORM_SEQUENCES: ClassVar[int] = 10   # the constants are settled by ten presses; a map
                                            # needs every place, so it takes every press

    BOUNDS: ClassVar[Mapping[str, Bound]] = MappingProxyType({
        "max_sequences": Bound(1, whole=True),
        "fold": Bound(0, whole=True),
        "start": Bound(K_MIN, K_MAX, unit="N/m"),      # each of the two
        "contact_radius": CONTACT_RADIUS,
        "spacing": SPACING,
        "workers": Bound(0, whole=True),
    })

    def __post_init__(self) -> None:
        check_bounds(self, self.BOUNDS)
        if self.regions is not None:
            parse_regions(f"{self.regions[0]}x{self.regions[1]}")

    def sequences_used(self) -> int | None:
        """How many sequences to read (None: every one)."""
        if self.max_sequences is not None:
            return self.max_sequences
        return None if self.map else self.UNIFORM_SEQUENCES

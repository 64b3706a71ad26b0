"""Every setting of ``pipeline fit-solid``, and the files it reads.

The fields' defaults are the command line's: ``pipeline/fit_solid_cmd.py`` reads them here.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import ClassVar

from core.bounds import Bound, check_bounds
from core.protocol import THICKNESS_M
from sim.solid.block_mesh import LAYERS, SPACING
from sim.solid.elasticity import POISSON
from sim.solid.solid_model import CONTACT_RADIUS, REACH


@dataclass(frozen=True)
class FitSolidInputs:
    """The measured states; optionally their fold manifest (fit on one fold's training
    presses), the session folder whose ``session.toml`` names the interior, and fit-msm's
    JSON (its distance is printed beside the solid's)."""

    states: Path
    splits: Path | None = None
    session: Path | None = None
    msm: Path | None = None


@dataclass(frozen=True)
class FitSolidParams:
    """Every setting of ``pipeline fit-solid``; bad input, in one line naming the setting,
    where one is out of its bounds."""

    fold: int = 0                    # the fold of ``splits`` whose training presses fit
    thickness: float = THICKNESS_M   # m, the block's
    spacing: float = 0.005           # m between the mesh's nodes across the footprint
    layers: int = 8                  # element layers through the thickness
    modulus: float = 2.0e4           # Pa, where the fit starts
    stiffening: float = 1000.0       # 1/m^2, where the fit starts (solid_model)
    poisson: float = 0.3             # the Poisson ratio (held unless fit_poisson)
    fit_poisson: bool = False        # also fit the Poisson ratio (a factorisation per step)
    contact_radius: float | None = None   # m, the tip's patch where the fit starts; None:
    #                                       1.2 mesh spacings
    reach: float = 0.02              # m, the stiffening's reach where the fit starts

    BOUNDS: ClassVar[Mapping[str, Bound]] = MappingProxyType({
        "fold": Bound(0, whole=True),
        "thickness": Bound(0.002, 0.5, unit="m"),
        "spacing": SPACING,
        "layers": LAYERS,
        "modulus": Bound(10.0, 1e8, unit="Pa"),
        "stiffening": Bound(1e-2, 1e6, unit="1/m^2"),
        "poisson": POISSON,
        "contact_radius": CONTACT_RADIUS,
        "reach": REACH,
    })

    def __post_init__(self) -> None:
        check_bounds(self, self.BOUNDS)

"""Every setting of ``pipeline simulate`` (and ``--merge``), and the files it may read.

The fields' defaults are the command line's: ``pipeline/simulate_cmd.py`` reads them here.
The protocol's and the model's defaults are the paper's (:mod:`sim.msm.paper`, through
:class:`~sim.msm.msm_protocol.Protocol`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import ClassVar

from core.bounds import Bound, check_bounds
from core.errors import BadInput
from core.protocol import FOOTPRINT_SIDE, THICKNESS_M
from sim.msm import paper
from sim.msm.msm_grid import SPACING
from sim.msm.msm_prior import PRIOR_DIRECTIONS, PRIOR_LOCATIONS
from sim.msm.msm_protocol import CONTACT_RADIUS, MAX_ANGLE, Protocol, parse_shard


@dataclass(frozen=True)
class SimulateInputs:
    """The files a simulation may read: a lab's states file whose markers it samples
    (``layout``), fit-msm's constants (``params_file``) or fit-solid's solid (``solid``)."""

    layout: Path | None = None
    params_file: Path | None = None
    solid: Path | None = None          # fit-solid's JSON: simulate the solid, not the MSM


@dataclass(frozen=True)
class SimulateParams:
    """Every setting of ``pipeline simulate``: the protocol, the springs, the grid, the
    solver, the run (workers, shard) and the recording."""

    locations: int | None = None       # None: the paper's 100; with prior, per phantom 4
    directions: int | None = None      # None: the paper's 11; with prior, per phantom 2
    steps: int = Protocol.steps
    fmax: float = Protocol.fmax                     # N
    max_angle_deg: float = Protocol.max_angle_deg
    seed: int = Protocol.seed
    contact_radius: float = Protocol.contact_radius  # m
    k_between: float = paper.K_BETWEEN              # N/m
    k_fixed: float = paper.K_FIXED                  # N/m
    size: tuple[float, float] | None = None         # m (L, W); None: layout, fit or paper
    spacing: float | None = None                    # m between masses; None: the paper's
    tol: float = paper.STATIC_TOL_N                 # N
    workers: int = 0                                # processes; 0: the cores we may use
    shard: str | None = None                        # "I/N": block I of N
    thickness: float = THICKNESS_M                  # m, the phantom's: deeper is counted
    rrd_sequences: int = 4                          # sequences shown in the recording
    prior: int = 0                                  # phantoms drawn from the prior, one
    #                                                 block each (sim.msm.msm_prior); 0: one MSM
    moulds: bool = False                            # the prior's phantoms curved moulds, their
    #                                                 solids pressed (sim.msm.mould_prior)

    SPRING: ClassVar[Bound] = Bound(0, 1e6, min_open=True, unit="N/m")
    BOUNDS: ClassVar[Mapping[str, Bound]] = MappingProxyType({
        "locations": Bound(1, whole=True), "directions": Bound(1, whole=True),
        "prior": Bound(0, whole=True), "steps": Bound(1, whole=True),
        "fmax": Bound(0, 1e3, min_open=True, unit="N", why="beyond any indentation"),
        "max_angle_deg": MAX_ANGLE, "contact_radius": CONTACT_RADIUS,
        "k_between": SPRING, "k_fixed": SPRING, "size": FOOTPRINT_SIDE, "spacing": SPACING,
        "tol": Bound(1e-9, 1e-2, unit="N", why="below 1e-9 N float64 cannot settle; above "
                                                "1e-2 N the states are not static"),
        "workers": Bound(0, whole=True),
        "thickness": Bound(0, 1, min_open=True, unit="m"),
        "rrd_sequences": Bound(0, whole=True),
    })

    def __post_init__(self) -> None:
        check_bounds(self, self.BOUNDS)
        if self.shard is not None:
            parse_shard(self.shard)
        if self.moulds and not self.prior:
            raise BadInput(None, "--moulds draws the prior's phantoms as moulds: give --prior N")
        if self.moulds and self.shard is not None:
            raise BadInput(None, "--moulds runs whole: no --shard (each mould's solid is "
                                 "factorised in its own worker; --workers spreads them)")
        if self.prior:
            drawn = [name for name in DRAWN if getattr(self, name) != getattr(DEFAULTS, name)]
            if drawn:
                raise BadInput(None, f"--prior draws the springs, the footprint and the "
                                     f"press: {', '.join(DRAWN[n] for n in drawn)} cannot be "
                                     "given with it")

    def protocol(self) -> Protocol:
        """The data-generation protocol these settings ask for (one MSM)."""
        return Protocol(locations=self.locations or Protocol.locations,
                        directions=self.directions or Protocol.directions, steps=self.steps,
                        fmax=self.fmax, max_angle_deg=self.max_angle_deg, seed=self.seed,
                        contact_radius=self.contact_radius)

    @property
    def places(self) -> tuple[int, int]:
        """Locations and directions per phantom of a prior run."""
        return self.locations or PRIOR_LOCATIONS, self.directions or PRIOR_DIRECTIONS


# settings a prior run draws itself (per phantom), with the options that set them
DRAWN = {"steps": "--steps", "fmax": "--fmax", "max_angle_deg": "--max-angle",
         "contact_radius": "--contact-radius", "k_between": "--k-between",
         "k_fixed": "--k-fixed", "size": "--size", "spacing": "--spacing-mm"}
DEFAULTS = SimulateParams()

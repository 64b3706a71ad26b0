"""Every setting of ``pipeline simulate`` (and ``--merge``), and the files it may read.

The fields' defaults are the command line's: ``pipeline/simulate_cmd.py`` reads them here.
The protocol's and the model's defaults are the paper's (:mod:`sim.msm.paper`, through
:class:`~sim.msm.msm_protocol.Protocol`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from core.protocol import THICKNESS_M
from sim.msm import paper
from sim.msm.msm_protocol import Protocol


@dataclass(frozen=True)
class SimulateInputs:
    """The files a simulation may read: a lab's states file whose markers it samples
    (``layout``) and fit-msm's constants (``params_file``)."""

    layout: Path | None = None
    params_file: Path | None = None


@dataclass(frozen=True)
class SimulateParams:
    """Every setting of ``pipeline simulate``: the protocol, the springs, the grid, the
    solver, the run (workers, shard) and the recording."""

    locations: int = Protocol.locations
    directions: int = Protocol.directions
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

    def protocol(self) -> Protocol:
        """The data-generation protocol these settings ask for."""
        return Protocol(locations=self.locations, directions=self.directions, steps=self.steps,
                        fmax=self.fmax, max_angle_deg=self.max_angle_deg, seed=self.seed,
                        contact_radius=self.contact_radius)

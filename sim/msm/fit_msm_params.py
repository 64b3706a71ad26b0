"""Every setting of ``pipeline fit-msm``, and the files it reads.

The fields' defaults are the command line's: ``pipeline/fit_msm_cmd.py`` reads them here.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from sim.msm import paper


@dataclass(frozen=True)
class FitMsmInputs:
    """The measured states, and optionally their fold manifest (fit on one fold's training
    presses only)."""

    states: Path
    splits: Path | None = None


@dataclass(frozen=True)
class FitMsmParams:
    """Every setting of ``pipeline fit-msm``."""

    max_sequences: int = 10             # sequences used (drawn with the seed when more)
    fold: int = 0                       # the fold of ``splits`` whose training presses fit
    start: tuple[float, float] = (paper.K_BETWEEN, paper.K_FIXED)   # N/m, the paper's
    contact_radius: float | None = None  # m; None: 0 for lab states, an MSM file's own
    spacing: float | None = None        # m between masses (lab states); None: the paper's
    workers: int = 0                    # processes; 0: the cores this process may use
    seed: int = 0

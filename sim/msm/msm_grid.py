"""The MSM's surface sized to a phantom's footprint, and what a fitted grid may be used for.

A lab's phantom is an L x W rectangle in the phantom frame ([0, L] x [0, W], the rest surface
at z = 0). Its MSM keeps the paper's mass spacing (100/31 mm) unless told otherwise: along each
axis ``n = round(L / h) + 1`` masses (at least 2), spaced ``L / (n - 1)`` so the grid covers
the footprint exactly. The paper's 100 mm square gives its 32 x 32 masses.

Spring constants are fitted on one grid: ``simulate --params`` uses the grid the fit was made
on, and refuses a footprint or spacing that asks for another (:func:`check_same_grid`).
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

from core.bounds import Bound
from core.errors import BadInput
from sim.msm import paper
from sim.msm.msm import MSMError, MSMParams

PAPER_SPACING_M = paper.SIZE_M / (paper.GRID_N - 1)     # 100/31 mm
MAX_MASSES = 100_000      # ~316 x 316: a static solve of that many masses takes seconds
SAME_SIZE_M = 1e-6        # m: footprints this close are one (float32 attributes, mm options)
SPACING = Bound(0, 0.1, min_open=True, unit="m")   # the masses' spacing, when one is asked
GRID_KEYS = ("n", "size", "n_y", "size_y")


def masses_along(length: float, spacing: float = PAPER_SPACING_M) -> int:
    """Masses along a side of ``length`` (m) at about ``spacing`` (m): round(L / h) + 1, >= 2."""
    return max(2, math.floor(length / spacing + 0.5) + 1)


def grid_params(footprint: tuple[float, float], spacing: float | None = None,
                base: MSMParams | None = None) -> MSMParams:
    """``base`` (default the paper's parameters) with its grid sized to ``footprint`` (L, W)
    in m at about ``spacing`` m (default the paper's), covering [0, L] x [0, W] exactly."""
    length, width = (float(v) for v in footprint)
    h = PAPER_SPACING_M if spacing is None else float(spacing)
    if not (math.isfinite(h) and 0 < h <= min(length, width)):
        raise BadInput("--spacing-mm", f"{h * 1e3:g} mm: the masses' spacing must be a "
                                       f"positive length within the footprint's "
                                       f"{min(length, width) * 1e3:g} mm side")
    n, n_y = masses_along(length, h), masses_along(width, h)
    if n * n_y > MAX_MASSES:
        raise BadInput("--spacing-mm", f"{h * 1e3:g} mm on {length * 1e3:g} x {width * 1e3:g} "
                                       f"mm asks for {n} x {n_y} masses, beyond the "
                                       f"{MAX_MASSES:,} this solver is sized for: a coarser "
                                       "spacing")
    return replace(base or MSMParams(), n=n, size=length, n_y=n_y, size_y=width)


def describe(params: MSMParams) -> str:
    """``150 x 80 mm of 48 x 26 masses`` for messages."""
    return (f"{params.size * 1e3:g} x {params.width * 1e3:g} mm of {params.n} x {params.n_y} "
            "masses")


def same_grid(a: MSMParams, b: MSMParams) -> bool:
    """Whether two parameter sets have one grid: the same masses over the same footprint."""
    return (a.n, a.n_y) == (b.n, b.n_y) and all(
        abs(x - y) <= SAME_SIZE_M for x, y in zip(a.footprint, b.footprint, strict=True))


def check_same_grid(fitted: MSMParams, asked: MSMParams, source: str | Path, why: str) -> None:
    """Refuse, in one line naming ``source`` (the fit's file), a grid other than the one the
    constants were fitted on; ``why`` says what asked for it (e.g. ``--size 100x100``)."""
    if not same_grid(fitted, asked):
        raise BadInput(source, f"its spring constants were fitted on {describe(fitted)}, but "
                               f"{why} asks for {describe(asked)}: fit the MSM on this "
                               "phantom's states, or leave the size to the fit")


def recorded_grid(record: dict, source: str | Path) -> MSMParams | None:
    """The grid of an ``msm_params`` record (``n``, ``size``; ``n_y``, ``size_y`` where the
    grid is not square), as the paper's other parameters; None where it names no grid."""
    grid = {k: record[k] for k in GRID_KEYS if k in record}
    if not {"n", "size"} <= set(grid):
        return None
    try:
        return MSMParams(**grid)
    except (MSMError, TypeError) as e:
        raise BadInput(source, f"its msm_params grid is unusable: {getattr(e, 'what', e)}"
                       ) from None

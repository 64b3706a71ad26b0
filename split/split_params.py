"""Every setting of ``pipeline split``, and the data's defaults where the user gives none.

The fields' defaults are the command line's: ``pipeline/split_cmd.py`` reads them here.
"""

from __future__ import annotations

from dataclasses import dataclass

# by the states file's source: the grouping and the train:val:test ratio (the paper's for
# lab presses; by place for the MSM, whose locations are its presses' places)
DEFAULTS = {"lab": ("sequence", (12, 3, 5)), "msm": ("location", (7, 2, 1))}


@dataclass(frozen=True)
class SplitParams:
    """Every setting of ``pipeline split``: None where the data's default (:data:`DEFAULTS`,
    by the states file's source) applies. The runner fills those in before it splits, and
    the manifest's provenance records the settings so completed."""

    group_by: str | None = None                     # sequence | location
    ratio: tuple[int, int, int] | None = None       # train:val:test group counts
    folds: int = 5
    seed: int = 0

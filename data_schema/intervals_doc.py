"""A metrics row's ``intervals`` (``phantom.metrics`` 1.2 on): how the calibrated intervals
held on the test presses, as types, and their check.

Per reported level (:class:`IntervalLevel`) the share of test points inside their radius and
the mean radius (mm), the share of test examples whose change of force lies in its interval
and the mean half-width (N), and (1.5) the ``[low, high]`` range each share falls in by chance
(``band``, ``force_band``; train/evaluation/coverage_band.py); the same at 90 % by distance from
the tip's path (:class:`DistanceBin`, the surface's points; the tip's own point, where the
data have one, apart as ``tip_point``); the mean 90 % radius over the mean L_d
(``radius_to_ld``); and for a run the calibration's presses and examples
(:class:`Calibration`). Written by train/evaluation/coverage.py, read through these types by
every table and target.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from core.errors import BadInput
from data_schema.json_docs import check_numbers, check_shares, typed_keys
from data_schema.json_rows import NUMBER, JsonRow, strictly, written_if_set


@dataclass(frozen=True, kw_only=True)
class IntervalLevel(JsonRow):
    """One reported level's coverage on the test presses."""

    level: float = strictly(float)       # the intervals' level, in (0, 1)
    points: int                          # test points
    coverage: float                      # the share of them inside their radius
    mean_radius_mm: float | None         # None: a radius unbounded
    examples: int                        # test examples
    force_coverage: float                # the share of them whose |dF error| is inside
    force_half_width_n: float | None     # None: a half-width unbounded
    band: list[float] | None = written_if_set()         # 1.5: [low, high] by chance
    force_band: list[float] | None = written_if_set()   # 1.5: the force's


@dataclass(frozen=True, kw_only=True)
class DistanceBin(JsonRow):
    """The coverage at 90 % of the points between two distances from the tip's path."""

    from_mm: float
    to_mm: float | None                  # None: beyond the last edge
    points: int
    coverage: float
    mean_radius_mm: float | None


@dataclass(frozen=True, kw_only=True)
class Calibration(JsonRow):
    """The validation presses (and their examples) a run's intervals were calibrated on."""

    presses: int
    examples: int


@dataclass(frozen=True, kw_only=True)
class Intervals(JsonRow):
    """A row's intervals (see the module)."""

    levels: list[IntervalLevel]
    by_distance: list[DistanceBin]
    radius_to_ld: float | None           # the mean 90 % radius over the mean L_d
    tip_point: DistanceBin | None = written_if_set()     # the tip's own point, where one is
    calibration: Calibration | None = written_if_set()   # a run's (not a pooled row's)

    def at(self, level: float) -> IntervalLevel | None:
        """The reported level ``level`` (to 1e-9), if it is one."""
        return next((v for v in self.levels if abs(v.level - level) < 1e-9), None)


SHARES = ("coverage", "force_coverage")          # the keys that are shares in [0, 1]
BANDS = ("band", "force_band")                   # a level's [low, high] pairs


def check_intervals(path: str | Path, doc: dict, where: str) -> None:
    """A row's intervals: each level in (0, 1) with shares in [0, 1] over at least one point
    and example, widths finite and plausible or null (unbounded); the distance bins alike."""
    typed_keys(path, doc, Intervals.kinds(), where, optional=Intervals.optional())
    if "calibration" in doc:
        typed_keys(path, doc["calibration"], Calibration.kinds(), f"{where}.calibration")
    items: list[tuple[type[JsonRow], str, Any]] = [
        (IntervalLevel, f"{where}.levels[{i}]", item) for i, item in enumerate(doc["levels"])]
    items += [(DistanceBin, f"{where}.by_distance[{i}]", item)
              for i, item in enumerate(doc["by_distance"])]
    if "tip_point" in doc:
        items.append((DistanceBin, f"{where}.tip_point", doc["tip_point"]))
    for row, here, item in items:
        typed_keys(path, item, row.kinds(), here, optional=row.optional())
        if row is IntervalLevel:
            _check_bands(path, item, here)
            if not 0 < item["level"] < 1:
                raise BadInput(path, f"{here}.level is {item['level']}: not in (0, 1)")
        check_shares(path, item, SHARES, here)
        check_numbers(path, {k: v for k, v in item.items()
                             if v is not None and k not in BANDS}, here)
        if item["points"] < 1 or item.get("examples", 1) < 1:
            raise BadInput(path, f"{here} must count at least one point and example")


def _check_bands(path: str | Path, item: dict, where: str) -> None:
    """Each band a level has is a [low, high] pair of shares, low at most high."""
    for key in BANDS:
        pair = item.get(key)
        if pair is None:
            continue
        if not (len(pair) == 2 and all(isinstance(v, NUMBER) and not isinstance(v, bool)
                                       and 0 <= v <= 1 for v in pair) and pair[0] <= pair[1]):
            raise BadInput(path, f"{where}.{key} is {pair!r}: not a [low, high] pair of "
                                 "shares in [0, 1]")

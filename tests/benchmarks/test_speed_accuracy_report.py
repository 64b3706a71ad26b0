"""The speed-accuracy report's choices (benchmarks/speed_accuracy_report.py) on known rows."""

from __future__ import annotations

import sys

from helpers.paths import ROOT

sys.path.insert(0, str(ROOT / "benchmarks"))

from speed_accuracy_report import pareto, pick, table  # noqa: E402

ROWS = [{"setting": "a", "ms": 1.0, "err": 0.50}, {"setting": "b", "ms": 2.0, "err": 0.40},
        {"setting": "c", "ms": 3.0, "err": 0.45}, {"setting": "d", "ms": 4.0, "err": 0.30},
        {"setting": "e", "ms": 0.5, "err": 0.302}, {"setting": "unsupported"}]


def test_the_pareto_front_keeps_only_rows_nothing_beats() -> None:
    front = [r["setting"] for r in pareto(ROWS[:4], "ms", "err")]
    assert front == ["a", "b", "d"]                    # c is beaten by b on both
    assert [r["setting"] for r in pareto(ROWS, "ms", "err")] == ["e", "d"]   # e beats a, b


def test_pick_fits_the_budget_and_breaks_near_ties_by_cost() -> None:
    assert pick(ROWS[:4], "ms", 2.5, "err")["setting"] == "b"
    assert pick(ROWS[:4], "ms", 0.1, "err") is None
    assert pick(ROWS, "ms", 10.0, "err")["setting"] == "e"       # 0.302 is within 2 % of 0.30


def test_a_missing_value_is_a_dash() -> None:
    text = table(ROWS[-2:], [("setting", "s", "s"), ("ms", "ms", ".1f")])
    assert text.splitlines()[-1] == "| unsupported | - |"


def test_the_default_region_is_the_smallest_within_tolerance_at_every_size() -> None:
    from region_study import RADII_MM, pick_default

    def rows(n: int, whole: float, by_radius: dict[float, float]) -> list[dict]:
        return [{"points": n, "setting": "whole model", "ld_mm": whole}] + [
            {"points": n, "radius_mm": r, "ld_mm": by_radius.get(r, whole)} for r in RADII_MM]

    small, middle = RADII_MM[0], RADII_MM[2]
    assert pick_default(rows(1024, 1.0, {small: 1.2, RADII_MM[1]: 1.04})
                        + rows(4096, 2.0, {small: 2.5, RADII_MM[1]: 2.12})) == middle
    assert pick_default(rows(1024, 1.0, {r: 1.3 for r in RADII_MM})) is None

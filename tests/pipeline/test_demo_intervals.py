"""The demo's interval targets: met by coverage at the levels, missed by coverage off them,
by huge radii, by radii that do not fall with distance, and by runs without intervals; the
scarcity study's models with the fewest presses alike."""

from __future__ import annotations

import copy

from pipeline.demo_targets import _intervals, _scarce_intervals


def _run(fold: int, shift: float = 0.0, ratio: float = 2.0, far_mm: float = 0.1) -> dict:
    levels = [{"level": q, "coverage": q + shift, "force_coverage": q + shift}
              for q in (0.8, 0.9, 0.95)]
    near = [{"mean_radius_mm": 0.5}, {"mean_radius_mm": far_mm}]
    return {"run": f"runs/exp_tl_fold{fold}", "fold": fold,
            "variant": {"pretrained": {"model": "cGNN"}, "train_data": "Exp"},
            "intervals": {"levels": levels, "radius_to_ld": ratio, "by_distance": near}}


def _ok(runs: list[dict]) -> list[bool]:
    return [ok for _, ok, _ in _intervals({"runs": runs})]


def test_coverage_at_the_levels_meets_every_target() -> None:
    assert _ok([_run(0), _run(1, shift=0.02)]) == [True] * 4


def test_each_way_to_miss_is_named() -> None:
    assert _ok([_run(0), _run(1, shift=-0.06)])[:2] == [False, False]   # one fold off
    assert _ok([_run(0, ratio=3.5)])[2] is False                        # covering by size
    assert _ok([_run(0, far_mm=0.9)])[3] is False                       # far not smaller
    none = copy.deepcopy(_run(0))
    none["intervals"] = None
    ((name, ok, text),) = _intervals({"runs": [none]})
    assert not ok and "absent" in text


def _scarce(groups: int, points: float | None, force: float | None, predictor: str = "TL"
            ) -> dict:
    return {"fold": 0, "groups": groups, "predictor": predictor, "points_90": points,
            "force_90": force}


def test_the_scarcity_studys_fewest_presses_are_held_to_the_same_shares() -> None:
    refs = {"fold": 0, "groups": 1, "predictor": "nothing moves"}     # no intervals
    met = [_scarce(1, 0.91, 0.88), _scarce(1, 0.89, 0.93, "no TL"), _scarce(2, 0.5, 0.5), refs]
    ((name, ok, text),) = _scarce_intervals(met)
    assert ok and "1 training press " in name and "fold 0 TL: points 91.0%" in text
    assert not _scarce_intervals([_scarce(1, 0.85, 0.90), refs])[0][1]    # points off
    assert not _scarce_intervals([_scarce(1, 0.90, 0.97), refs])[0][1]    # force off
    assert _scarce_intervals([_scarce(1, None, None), refs]) == []        # none kept

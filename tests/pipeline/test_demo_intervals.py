"""The demo's interval targets: met by pooled shares inside the range re-drawn calibrations
give, missed by a share outside it or without one, by huge radii, by radii that do not fall
with distance, and by runs without intervals; the scarcity study's models with the fewest
presses alike, each inside its fold's range."""

from __future__ import annotations

from dataclasses import replace

from helpers.metrics_rows import level, pooled_row, run_row, variant

from data_schema.intervals_doc import DistanceBin, IntervalLevel, Intervals
from data_schema.metrics_doc import RunRow, ScarcityRow, ScarcityShares, Scores
from pipeline.demo_targets import _intervals, _scarce_intervals

TL = variant(pretrained=variant("MSM"))
SCRATCH = variant()


def _levels(shift: float = 0.0, force_shift: float = 0.0, band: float | None = 0.04
            ) -> list[IntervalLevel]:
    """Each reported level's shares (the level plus a shift) with bands of +- ``band``
    around the level (none where None)."""
    return [level(level=q, coverage=q + shift, force_coverage=q + force_shift,
                  band=None if band is None else [q - band, q + band],
                  force_band=None if band is None else [q - 2 * band, q + 2 * band])
            for q in (0.8, 0.9, 0.95)]


def _bin(mean_radius_mm: float) -> DistanceBin:
    return DistanceBin(from_mm=10.0, to_mm=20.0, points=10, coverage=0.9,
                       mean_radius_mm=mean_radius_mm)


def _run(fold: int, ratio: float = 2.0, far_mm: float = 0.1, variant: dict = TL) -> RunRow:
    near = [_bin(0.5), _bin(far_mm)]
    return run_row(run=f"runs/exp_{'tl' if variant['pretrained'] else 'notl'}_fold{fold}",
                   fold=fold, variant=variant,
                   intervals=Intervals(levels=_levels(shift=-0.1), radius_to_ld=ratio,
                                       by_distance=near))


def _doc(runs: list[RunRow], **pooled: float | None) -> Scores:
    """Runs (each fold's shares far off: only the pooled rows are held to the bands) and
    the pooled rows of TL and scratch."""
    rows = [pooled_row(variant=v, intervals=Intervals(levels=_levels(**pooled),
                                                      by_distance=[], radius_to_ld=None))
            for v in (TL, SCRATCH)]
    return Scores(runs=runs, overall=rows)


def _ok(doc: Scores) -> list[bool]:
    return [ok for _, ok, _ in _intervals(doc)]


def test_pooled_shares_inside_their_bands_meet_every_target() -> None:
    runs = [_run(0), _run(1), _run(0, variant=SCRATCH)]
    assert _ok(_doc(runs)) == [True] * 4
    assert _ok(_doc(runs, shift=0.03, force_shift=-0.07)) == [True] * 4
    text = _intervals(_doc(runs))[0][2]
    assert "TL: 80.0% (76-84)" in text and "scratch: 80.0% (76-84)" in text


def test_each_way_to_miss_is_named() -> None:
    runs = [_run(0), _run(1)]
    assert _ok(_doc(runs, shift=-0.05))[:2] == [False, True]          # points outside
    assert _ok(_doc(runs, force_shift=0.09))[:2] == [True, False]     # force outside
    assert _ok(_doc(runs, band=None))[:2] == [False, False]           # no band measured
    assert _ok(_doc([_run(0, ratio=3.5)]))[2] is False                # covering by size
    assert _ok(_doc([_run(0, far_mm=0.9)]))[3] is False               # far not smaller
    none = replace(_run(0), intervals=None)
    ((name, ok, text),) = _intervals(_doc([none]))
    assert not ok and "absent" in text


def _scarce(groups: int, points: float | None, force: float | None, predictor: str = "TL",
            band: tuple[float, float] | None = (0.85, 0.95)) -> ScarcityRow:
    low, high = band or (None, None)
    return ScarcityRow(fold=0, groups=groups, predictor=predictor, ld_mean_mm=0.2,
                       ld_max_mm=0.5, force_abs_n=0.1,
                       shares=ScarcityShares(points_90=points, force_90=force,
                                             points_90_low=low, points_90_high=high,
                                             force_90_low=low, force_90_high=high))


def test_the_scarcity_studys_fewest_presses_are_held_to_their_bands() -> None:
    refs = ScarcityRow(fold=0, groups=1, predictor="nothing moves", ld_mean_mm=0.3,
                       ld_max_mm=0.9, force_abs_n=0.5)                # no intervals
    met = [_scarce(1, 0.91, 0.88), _scarce(1, 0.89, 0.93, "no TL"), _scarce(2, 0.5, 0.5),
           refs]
    ((name, ok, text),) = _scarce_intervals(met)
    assert ok and "1 training press " in name and "fold 0 TL: points 91.0% (85-95)" in text
    assert not _scarce_intervals([_scarce(1, 0.80, 0.90), refs])[0][1]    # points off
    assert not _scarce_intervals([_scarce(1, 0.90, 0.97), refs])[0][1]    # force off
    assert not _scarce_intervals([_scarce(1, 0.90, 0.90, band=None), refs])[0][1]
    assert _scarce_intervals([_scarce(1, None, None), refs]) == []        # none kept


def test_a_scarcity_model_with_one_share_missing_misses_and_says_which() -> None:
    """A model's row with the points' share and not the force's (or the reverse) misses the
    target, naming the share it lacks, however well the other sits in its band."""
    for points, force, missing in ((0.9, None, "force"), (None, 0.9, "points")):
        ((_, ok, text),) = _scarce_intervals([_scarce(1, points, force)])
        assert not ok and f"fold 0 TL: {missing} share missing" in text
        assert "90.0% (85-95)" in text                                  # the other one shown

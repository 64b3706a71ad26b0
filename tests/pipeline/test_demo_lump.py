"""The demo's targets over a lump and away from it: every fold with test presses there at
least 30 % below the best reference there; a fold with none is named, not counted."""

from __future__ import annotations

from dataclasses import replace

from helpers.metrics_rows import gain, metrics, run_row, variant

from data_schema.metrics_doc import LumpPart, LumpRow, RunRow, Scores
from pipeline.demo_targets import (
    LUMP_WORDS,
    _force_over_lump,
    _over_lump,
    _solid_over_lump,
    variant_of,
)


def _part(ld_gain: float | None, n: int = 12) -> LumpPart:
    return LumpPart(metrics=metrics(n=n), references={}, gain=gain(ld_gain=ld_gain),
                    intervals=None)


def _lump(over: LumpPart | None, away: LumpPart | None) -> LumpRow:
    return LumpRow(centre_mm=[72.0, 23.0], radius_mm=12.0, reach_mm=10.0, over=over,
                   away=away)


def _run(fold: int, over: LumpPart | None, away: LumpPart | None, pretrained: bool = True
         ) -> RunRow:
    return run_row(run=f"runs/exp_{'tl' if pretrained else 'notl'}_fold{fold}", fold=fold,
                   variant=variant(pretrained=variant("MSM") if pretrained else None),
                   lump=_lump(over, away))


def _scores(runs: list[RunRow]) -> Scores:
    return Scores(runs=runs, overall=[])


def _checks(runs: list[RunRow]) -> dict[str, tuple[bool, str]]:
    return {name: (ok, text) for name, ok, text in _over_lump(_scores(runs))}


def test_every_fold_over_and_away_meets_the_target() -> None:
    got = _checks([_run(0, _part(0.5), _part(0.6)), _run(1, None, _part(0.4)),
                   _run(0, _part(0.45), _part(0.5), pretrained=False)])
    assert set(got) == {"TL over the lump: mean L_d below the best reference",
                        "TL away from the lump: mean L_d below the best reference",
                        "scratch over the lump: mean L_d below the best reference",
                        "scratch away from the lump: mean L_d below the best reference"}
    assert all(ok for ok, _ in got.values())
    ok, text = got["TL over the lump: mean L_d below the best reference"]
    assert "fold 0: +50% (12 examples)" in text and "no test press there in fold(s) 1" in text


def test_the_targets_name_every_part_of_a_lump_in_its_order() -> None:
    """Each part the metrics document gives a lump (:meth:`LumpRow.parts`) has its words,
    and the targets come in its order: over the lump, then away from it."""
    parts = list(_lump(_part(0.5), None).parts())
    assert list(LUMP_WORDS) == parts
    got = [name for name, _, _ in _over_lump(_scores([_run(0, _part(0.5), _part(0.6))]))]
    assert got == [f"TL {LUMP_WORDS[p]}: mean L_d below the best reference" for p in parts]


def test_one_fold_short_over_the_lump_misses_and_none_there_misses() -> None:
    got = _checks([_run(0, _part(0.5), _part(0.6)), _run(1, _part(0.2), _part(0.6))])
    assert not got["TL over the lump: mean L_d below the best reference"][0]
    assert got["TL away from the lump: mean L_d below the best reference"][0]
    empty = _checks([_run(0, None, _part(0.6))])
    assert not empty["TL over the lump: mean L_d below the best reference"][0]


def test_runs_without_a_lump_add_no_target() -> None:
    plain = replace(_run(0, None, None), lump=None)
    assert _over_lump(_scores([plain])) == []


def _over(ld: float, force: float, n: int) -> LumpPart:
    return LumpPart(metrics=metrics(n=n, ld_mean_mm=ld, force_abs_n=force), references={},
                    gain=gain(ld_gain=0.5), intervals=None)


def _from(fold: int, source: str, over: LumpPart | None) -> RunRow:
    return run_row(run=f"runs/exp_{source}_fold{fold}", fold=fold,
                   variant=variant(pretrained=variant(source)),
                   lump=_lump(over, _over(0.1, 0.1, 50)))


def test_tl_from_the_solid_is_held_to_15_percent_below_the_shipped_models_over_the_lump(
        ) -> None:
    """Pooled over the folds with presses there (weighted by their examples)."""
    runs = [_from(0, "MSM", _over(0.20, 0.3, 10)), _from(1, "MSM", _over(0.10, 0.2, 30)),
            _from(0, "Solid", _over(0.15, 0.2, 10)), _from(1, "Solid", _over(0.08, 0.1, 30)),
            _from(2, "Solid", None)]
    (name, ok, text), = _solid_over_lump(_scores(runs))
    # generic: (0.2 * 10 + 0.1 * 30) / 40 = 0.125; solid: (0.15 * 10 + 0.08 * 30) / 40 = 0.0975
    assert ok and "0.0975 against 0.1250 mm (+22%)" in text
    assert "TL from the solid" in name
    runs[3] = _from(1, "Solid", _over(0.11, 0.1, 30))          # (1.5 + 3.3) / 40 = 0.12: 4 %
    assert not _solid_over_lump(_scores(runs))[0][1]
    assert _solid_over_lump(_scores(runs[:2])) == []            # no solid runs: no target
    assert {variant_of(r) for r in runs} == {"tl", "solid"}


def test_the_force_over_the_lump_is_held_to_1_3_times_the_force_away() -> None:
    """Pooled over the folds: TL over (0.3 x 10 + 0.1 x 30) / 40 = 0.15 N against 0.1 away
    (1.5 x: missed); the solid's (0.12 x 10 + 0.13 x 30) / 40 = 0.1275 N (1.27 x: met)."""
    runs = [_from(0, "MSM", _over(0.2, 0.3, 10)), _from(1, "MSM", _over(0.1, 0.1, 30)),
            _from(0, "Solid", _over(0.2, 0.12, 10)), _from(1, "Solid", _over(0.1, 0.13, 30))]
    got = {name: (ok, text) for name, ok, text in _force_over_lump(_scores(runs))}
    tl = got["TL: the force's error over the lump against away from it"]
    solid = got["TL from the solid: the force's error over the lump against away from it"]
    assert not tl[0] and "0.150 against 0.100 N (1.50 x" in tl[1]
    assert solid[0] and "0.128 against 0.100 N (1.27 x" in solid[1]
    assert _force_over_lump(_scores([replace(runs[0], lump=None)])) == []


def test_a_curved_labs_tl_runs_are_told_from_its_solids() -> None:
    """On a curved lab TL starts from the model for curved labs (pre-trained on the moulds'
    solids, itself from the MSM prior's): a TL run, not one from the lab's own solid."""
    moulds = variant("Moulds", pretrained=variant("MSM"))
    tl = run_row(run="runs/exp_tl_fold0", fold=0, variant=variant(pretrained=moulds))
    solid = run_row(run="runs/exp_solid_fold0", fold=0,
                    variant=variant(pretrained=variant("Solid", pretrained=moulds)))
    assert (variant_of(tl), variant_of(solid)) == ("tl", "solid")

"""The demo's targets over a lump and away from it: every fold with test presses there at
least 30 % below the best reference there; a fold with none is named, not counted."""

from __future__ import annotations

from pipeline.demo_targets import _over_lump


def _part(gain: float | None, n: int = 12) -> dict:
    return {"metrics": {"n": n}, "gain": {"ld_gain": gain}}


def _run(fold: int, over: dict | None, away: dict | None, pretrained: bool = True) -> dict:
    return {"run": f"runs/exp_{'tl' if pretrained else 'notl'}_fold{fold}", "fold": fold,
            "variant": {"pretrained": {"model": "cGNN"} if pretrained else None,
                        "train_data": "Exp"},
            "lump": {"centre_mm": [72.0, 23.0], "radius_mm": 12.0, "over": over,
                     "away": away}}


def _checks(runs: list[dict]) -> dict[str, tuple[bool, str]]:
    return {name: (ok, text) for name, ok, text in _over_lump({"runs": runs})}


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


def test_one_fold_short_over_the_lump_misses_and_none_there_misses() -> None:
    got = _checks([_run(0, _part(0.5), _part(0.6)), _run(1, _part(0.2), _part(0.6))])
    assert not got["TL over the lump: mean L_d below the best reference"][0]
    assert got["TL away from the lump: mean L_d below the best reference"][0]
    empty = _checks([_run(0, None, _part(0.6))])
    assert not empty["TL over the lump: mean L_d below the best reference"][0]


def test_runs_without_a_lump_add_no_target() -> None:
    plain = _run(0, None, None)
    del plain["lump"]
    assert _over_lump({"runs": [plain]}) == []

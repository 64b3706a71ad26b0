"""k-fold split manifests over a states file (``phantom.folds`` 2.0), grouped by press or place.

Groups (``states/sequence``: one press or MSM location x direction; or ``states/location``:
one place) never cross roles within a fold. A ratio train:val:test of the G groups gives
n_test = round(G c / (a + b + c)), n_val = round(G b / (a + b + c)), the rest train. Groups are
shuffled once with the seed; where presses repeat places (each group's place given), they are
then dealt place by place, so that neighbours in the order lie at different places and every
fold's test and validation presses spread over the places (a fold that tests most presses of
one place while calibrating its intervals on none of them covers by chance: docs/results.md,
"Why the force's interval missed"). Fold f tests the n_test groups starting at round(f G / K)
of that order (cyclically), so test sets are disjoint when K n_test <= G and cover every group when
K n_test >= G (the manifest's ``note`` says which held); validation groups are taken from the
remaining ones, turning with the fold; training subsets 1..n are prefixes of a seeded order of
the fold's training groups (nested, for the data-scarcity study). An example belongs to the group
of its states (start and end are in one sequence, and a sequence is at one location).

Pure numpy: importing it does not load torch.
"""

from __future__ import annotations

import numpy as np

from core.errors import BadInput
from split.split_params import SplitParams, check_ratio, filled_in


def parse_ratio(text: str) -> tuple[int, int, int]:
    """``"12:3:5"`` -> (12, 3, 5); one line naming the text when it is not three counts."""
    try:
        parts = tuple(int(v) for v in text.split(":"))
    except ValueError:
        parts = ()
    check_ratio(parts, text)
    return parts  # type: ignore[return-value]


def role_counts(n_groups: int, ratio: tuple[int, int, int]) -> tuple[int, int, int]:
    """Groups in train, val and test; an error naming the numbers when one role gets none."""
    total = sum(ratio)
    n_test = round(n_groups * ratio[2] / total)
    n_val = round(n_groups * ratio[1] / total)
    n_train = n_groups - n_test - n_val
    if n_test < 1 or n_train < 1 or (ratio[1] > 0 and n_val < 1):
        raise BadInput(None, f"ratio {':'.join(map(str, ratio))} does not fit {n_groups} "
                             f"group(s): it gives train {n_train}, val {n_val}, test {n_test}; "
                             "every role needs at least one group")
    return n_train, n_val, n_test


def make_folds(groups: np.ndarray, plan: SplitParams, places: dict[int, int] | None = None
               ) -> tuple[list[dict], str]:
    """Per fold the train/val/test group ids and the nested training subsets, and a note;
    ``plan`` with the data's defaults filled in (its ``ratio`` given); ``places``: each
    group's place, where groups repeat places (:func:`spread_over_places`)."""
    ids = np.unique(groups)
    g = len(ids)
    if plan.folds < 1:
        raise BadInput(None, f"--folds must be at least 1, got {plan.folds}")
    n_train, n_val, n_test = role_counts(g, filled_in(plan)[1])
    rng = np.random.default_rng(plan.seed)
    order = ids[rng.permutation(g)]
    spread = False
    if places is not None and len(set(places.values())) < g:
        order, spread = spread_over_places(order, places, rng), True
    folds = []
    for f in range(plan.folds):
        start = round(f * g / plan.folds)
        test = [order[(start + i) % g] for i in range(n_test)]
        rest = [x for x in order if x not in set(test)]
        turn = (f * n_val) % len(rest)
        rest = rest[turn:] + rest[:turn]
        val, train = rest[:n_val], rest[n_val:]
        train = [train[i] for i in rng.permutation(len(train))]
        folds.append({"fold": f, "groups": {"train": train, "val": val, "test": test},
                      "train_subsets": [train[:n] for n in range(1, len(train) + 1)]})
    note = _note(g, n_test, plan.folds)
    return folds, note + ("; presses dealt place by place" if spread else "")


def spread_over_places(order: np.ndarray, places: dict[int, int], rng: np.random.Generator
                       ) -> np.ndarray:
    """The groups of ``order`` dealt place by place: the places in a seeded order, each turn
    the next group (in ``order``) of every place that has one left."""
    by_place: dict[int, list] = {}
    for group in order:
        by_place.setdefault(int(places[int(group)]), []).append(group)
    keys = sorted(by_place)
    piles = [by_place[keys[i]] for i in rng.permutation(len(keys))]
    dealt = [pile[turn] for turn in range(max(map(len, piles))) for pile in piles
             if turn < len(pile)]
    return np.array(dealt, dtype=order.dtype)


def _note(g: int, n_test: int, folds: int) -> str:
    covered = folds * n_test
    if covered == g:
        return f"test sets are disjoint and cover all {g} groups"
    if covered > g:
        return (f"test sets overlap: {folds} folds x {n_test} test groups > {g} groups; "
                "they cover every group")
    return (f"test sets are disjoint but cover {covered} of {g} groups: "
            f"{folds} folds x {n_test} test groups < {g}")


def examples_by_role(example_group: dict[str, np.ndarray], roles: dict[str, list]
                     ) -> dict[str, dict[str, list[int]]]:
    """For each role, its groups and the ids of the single/multi examples in them."""
    out = {}
    for role, groups in roles.items():
        keep = np.asarray(groups)
        out[role] = {"groups": [int(x) for x in groups]}
        for name, eg in example_group.items():
            out[role][name] = np.flatnonzero(np.isin(eg, keep)).tolist()
    return out

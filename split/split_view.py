"""The split recording: which presses or places does each fold train, validate and test on?

Timeline ``fold`` (0..K-1). Entities: ``footprint/train``, ``footprint/val``, ``footprint/test``:
each group's place on the phantom footprint (x, y in mm: the tip where the press began),
coloured by role (train blue, val orange, test red); ``footprint/outline`` the phantom's
footprint; ``folds`` a text line per fold with its counts.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from core.recording import recording

APP_ID = "phantom-split"
ROLE_COLORS = {"train": (60, 120, 230), "val": (245, 150, 30), "test": (225, 45, 45)}


def blueprint() -> rrb.Blueprint:
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial2DView(name="fold roles on the footprint [mm]: train blue, val orange, "
                                   "test red", origin="/footprint"),
            rrb.TextLogView(name="folds", origin="/folds"),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


def group_places(states: str | Path, group_by: str) -> dict[int, np.ndarray]:
    """Each group's place (x, y, mm): the mean of its sequences' first tip positions."""
    with h5py.File(states, "r") as f:
        tip, step = f["states/tip"][()], f["states/step"][()]
        group, seq = f[f"states/{group_by}"][()], f["states/sequence"][()]
    places: dict[int, list] = {}
    for s in np.unique(seq):
        rows = np.flatnonzero(seq == s)
        first = rows[np.argmin(step[rows])]
        places.setdefault(int(group[first]), []).append(tip[first, :2] * 1e3)
    return {g: np.mean(v, axis=0) for g, v in places.items()}


FAN_MM = 3.0        # groups that share a place are drawn this far around it, each its own dot


def fanned(places: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
    """Each group's place, those that share one (within 1 mm: repeats of a press) set around
    it on a circle of :data:`FAN_MM`, so that every group's role shows (not the last drawn)."""
    shared: dict[tuple, list[int]] = {}
    for g in sorted(places):
        shared.setdefault(tuple(np.round(places[g]).astype(int)), []).append(g)
    out = {}
    for members in shared.values():
        for k, g in enumerate(members):
            turn = 2 * np.pi * k / len(members)
            step = FAN_MM * np.array([np.cos(turn), np.sin(turn)]) if len(members) > 1 else 0.0
            out[g] = places[g] + step
    return out


def write_split_recording(path: str | Path, states: str | Path, doc: dict) -> None:
    """Save the recording of the manifest ``doc`` over ``states`` to ``path``."""
    places = fanned(group_places(states, doc["group_by"]))
    lo = np.min(list(places.values()), axis=0) - 5
    hi = np.max(list(places.values()), axis=0) + 5
    with recording(APP_ID, path, blueprint()) as rec:
        box = [[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]], [lo[0], lo[1]]]
        rec.log("footprint/outline", rr.LineStrips2D([box], colors=[(180, 180, 180)]),
                static=True)
        for fold in doc["folds"]:
            rec.set_time("fold", sequence=fold["fold"])
            for role, color in ROLE_COLORS.items():
                xy = np.array([places[g] for g in fold[role]["groups"]]).reshape(-1, 2)
                rec.log(f"footprint/{role}", rr.Points2D(xy, colors=[color], radii=[1.5],
                                                         labels=[str(g) for g in
                                                                 fold[role]["groups"]]))
            rec.log("folds", rr.TextLog(
                f"fold {fold['fold']}: " + ", ".join(
                    f"{r} {len(fold[r]['groups'])} groups / {len(fold[r]['single'])} single "
                    f"+ {len(fold[r]['multi'])} multi" for r in ROLE_COLORS)))

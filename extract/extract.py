"""The extract stage's math: synced sessions -> the arrays of a states file (``phantom.states``).

Takes each session's presses in the phantom frame (:mod:`extract.synced_presses`), reads the
states off each loading phase (:mod:`extract.static_states`), numbers sequences in time order
across the sessions and builds the single- and multi-step examples.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from core.errors import BadInput
from core.progress import progress
from extract.static_states import ExtractParams, Press, PressStates, example_pairs, press_states
from extract.synced_presses import Session


@dataclass
class Extracted:
    """The arrays of a states file, and what was left out."""

    arrays: dict[str, np.ndarray]
    session_names: list[str]
    excluded: dict[str, int] = field(default_factory=dict)
    # per session, its presses and their states (empty for an excluded press): for the view
    sessions: list[tuple[list[Press], list[PressStates]]] = field(default_factory=list)


def extract(sessions: Sequence[Session], params: ExtractParams, seed: int = 0,
            shared_locations: bool = False) -> Extracted:
    """States and examples of every press of every session, in session then time order.

    Location ids are the files' own, offset per file unless ``shared_locations`` (the user
    says the same id is the same place in every session).
    """
    cols: dict[str, list] = {k: [] for k in ("points", "valid", "force", "step", "speed",
                                            "sequence", "location", "session")}
    names, transforms, excluded = [], [], {"no_loading_phase": 0, "tip_missing": 0,
                                           "too_fast": 0}
    seq = loc_offset = 0
    views = []
    for s_id, session in enumerate(sessions):
        names.append(session.name)
        transforms.append(session.transform)
        pairs = list(zip(session.presses, session.locations, strict=True))
        done = []
        with progress(pairs, f"extracting {session.path.name}") as bar:
            for press, loc in bar:
                if press.peak <= press.onset:
                    excluded["no_loading_phase"] += 1
                    st = press_states(press, params, levels=False)
                else:
                    st = press_states(press, params)
                    for k, v in st.dropped.items():
                        excluded[k] += v
                    _append(cols, st, seq, loc + loc_offset, s_id)
                done.append(st)
                seq += 1
        views.append((session.presses, done))
        if not shared_locations:
            loc_offset += max(session.locations) + 1
    if not cols["points"]:
        raise BadInput(sessions[0].path, "no static state in any press")
    arrays = {f"states/{k}": np.concatenate(v) for k, v in cols.items()}
    arrays["states/tip"] = arrays["states/points"][:, -1]
    arrays["sessions/transform"] = np.stack(transforms)
    single, multi = example_pairs(arrays["states/step"], arrays["states/sequence"],
                                  np.random.default_rng(seed))
    arrays.update({"single/start": single[:, 0], "single/end": single[:, 1],
                   "multi/start": multi[:, 0], "multi/end": multi[:, 1]})
    return Extracted(arrays, names, excluded, views)


def _append(cols: dict[str, list], st: PressStates, seq: int, loc: int, session: int) -> None:
    n = len(st.step)
    for key in ("points", "valid", "force", "step", "speed"):
        cols[key].append(getattr(st, key))
    for key, value in (("sequence", seq), ("location", loc), ("session", session)):
        cols[key].append(np.full(n, value))

"""The extract stage's math: synced sessions -> the arrays of a states file (``phantom.states``).

Takes each session's presses in the phantom frame (:mod:`extract.synced_presses`), reads the
states off each loading phase (:mod:`extract.static_states`), numbers sequences in time order
across the sessions and builds the single- and multi-step examples.

A press whose force sync flagged between onset and release (gauge voltages on the amplifier's
rail, or beyond the sensor's rated load) is left out whole, not from its first flagged frame:
a clipped force is wrong on the way up to the rail as well (the filter spreads the clip, and
the press's later levels would be read off a flat top), and a press without its top levels is
a different press. Its states are counted (``excluded["saturated_or_over_range"]``) and so are
the presses (:attr:`Extracted.untrusted_presses`). The level spacing is checked against the
sessions first (:func:`check_step`): above the force noise, below the largest peak.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from core.errors import BadInput
from core.progress import progress
from core.protocol import STEP_N
from data_schema.shape import Shape
from extract.extract_params import ExtractParams
from extract.static_states import PressSeries, PressStates, example_pairs, press_states
from extract.synced_presses import Session


@dataclass
class Extracted:
    """The arrays of a states file, and what was left out."""

    arrays: dict[str, np.ndarray]
    session_names: list[str]
    excluded: dict[str, int] = field(default_factory=dict)
    # per session, its presses and their states (empty for an excluded press): for the view
    sessions: list[tuple[list[PressSeries], list[PressStates]]] = field(default_factory=list)
    untrusted_presses: int = 0     # presses left out: force saturated or beyond rated range


def extract(sessions: Sequence[Session], params: ExtractParams) -> Extracted:
    """States and examples of every press of every session, in session then time order.

    Location ids are the files' own, offset per file unless ``params.shared_locations`` (the
    user says the same id is the same place in every session).
    """
    check_step(sessions, params.step_n)
    check_same_phantom(sessions)
    cols: dict[str, list] = {k: [] for k in ("points", "valid", "force", "step", "speed",
                                            "sequence", "location", "session")}
    names, transforms = [], []
    excluded = {"no_loading_phase": 0, "tip_missing": 0, "too_fast": 0,
                "saturated_or_over_range": 0}
    seq = loc_offset = untrusted = 0
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
                elif press.untrusted_force:
                    untrusted += 1
                    excluded["saturated_or_over_range"] += len(press_states(press, params).step)
                    st = press_states(press, params, levels=False)
                else:
                    st = press_states(press, params)
                    for k, v in st.dropped.items():
                        excluded[k] += v
                    _append(cols, st, seq, loc + loc_offset, s_id)
                done.append(st)
                seq += 1
        views.append((session.presses, done))
        if not params.shared_locations:
            loc_offset += max(session.locations) + 1
    if not cols["points"]:
        why = (f": all {untrusted} presses have a saturated or over-range force (flagged by "
               "sync)" if untrusted == seq else "")
        raise BadInput(sessions[0].path, f"no static state in any press{why}")
    arrays = {f"states/{k}": np.concatenate(v) for k, v in cols.items()}
    arrays["states/tip"] = arrays["states/points"][:, -1]
    arrays["sessions/transform"] = np.stack(transforms)
    single, multi = example_pairs(arrays["states/step"], arrays["states/sequence"],
                                  np.random.default_rng(params.seed))
    arrays.update({"single/start": single[:, 0], "single/end": single[:, 1],
                   "multi/start": multi[:, 0], "multi/end": multi[:, 1]})
    return Extracted(arrays, names, excluded, views, untrusted)


def check_same_phantom(sessions: Sequence[Session]) -> None:
    """One states file holds one phantom: every session with the same markers in the same
    order, the same footprint and the same shape (a point is a marker, the frame the
    footprint's, or the mould's)."""
    first = sessions[0]
    for s in sessions[1:]:
        if s.point_names != first.point_names:
            raise BadInput(s.path, f"its {len(s.point_names) - 1} phantom markers are not those "
                                   f"of {first.path.name} ({len(first.point_names) - 1}, in the "
                                   "same order): one states file holds one phantom")
        if not np.allclose(s.layout.size_m, first.layout.size_m, rtol=0, atol=1e-9):
            raise BadInput(s.path, f"its footprint {_mm(s.layout.size_m)} is not that of "
                                   f"{first.path.name} ({_mm(first.layout.size_m)})")
        if not _same_shape(s.layout.shape, first.layout.shape):
            raise BadInput(s.path, f"its phantom's shape is not that of {first.path.name} "
                                   "(flat, or another mould): its frame is another")


def _same_shape(a: Shape | None, b: Shape | None) -> bool:
    """Whether two layouts' shapes are one (both flat, or the same surface)."""
    if a is None or b is None:
        return a is b
    return (a.faces.shape == b.faces.shape and a.vertices.shape == b.vertices.shape
            and np.array_equal(a.faces, b.faces) and np.allclose(a.vertices, b.vertices,
                                                                 rtol=0, atol=1e-9))


def _mm(size_m: tuple[float, float]) -> str:
    return "x".join(f"{v * 1e3:g}" for v in size_m) + " mm"


RESOLUTION_N = 1 / 320     # an ATI Nano17 SI-12-0.12's force resolution (N)
NOISE_WIDTHS = 3.0         # levels closer than this many noise sd are not distinct readings


def step_floor_n(sessions: Sequence[Session]) -> float:
    """The finest meaningful level spacing (N): :data:`NOISE_WIDTHS` times the largest force
    noise sync measured, and never below the Nano17's resolution."""
    return max(RESOLUTION_N, NOISE_WIDTHS * max(s.noise_n for s in sessions))


def check_step(sessions: Sequence[Session], step_n: float) -> None:
    """Refuse a level spacing that is not finite and positive, finer than the force noise
    (:func:`step_floor_n`: the levels would be noise, and their count unbounded), or coarser
    than the largest peak force (no level but the rest)."""
    if not (np.isfinite(step_n) and step_n > 0):
        raise BadInput(None, f"--step {step_n:g} N: must be a finite force level spacing > 0")
    floor = step_floor_n(sessions)
    if step_n < floor:
        noise = max(s.noise_n for s in sessions)
        raise BadInput(None, f"--step {step_n:g} N: below the force noise floor {floor:.4g} N "
                             f"({NOISE_WIDTHS:g} x the {noise:.4g} N noise sync measured, and at "
                             f"least 1/320 N, a Nano17's resolution): its levels would be "
                             f"noise (default {STEP_N:g} N)")
    peak = max((float(np.nanmax(p.force)) for s in sessions for p in s.presses
                if np.isfinite(p.force).any()), default=0.0)
    if step_n > peak:
        raise BadInput(None, f"--step {step_n:g} N: above the largest peak force of the "
                             f"presses ({peak:.3g} N): no level but the rest would be read")


def _append(cols: dict[str, list], st: PressStates, seq: int, loc: int, session: int) -> None:
    n = len(st.step)
    for key in ("points", "valid", "force", "step", "speed"):
        cols[key].append(getattr(st, key))
    for key, value in (("sequence", seq), ("location", loc), ("session", session)):
        cols[key].append(np.full(n, value))

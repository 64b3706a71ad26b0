"""The scene of a synthetic session: its parameters, where the phantom stands, where it is
pressed, and the phantom solved along each press.

The phantom frame (bottom centre of the block, z up) is placed on the table, turned a little
about the vertical (:func:`placement`); the locations (places) are top lattice nodes a press
may target (two lattice spacings clear of every marker, 20 mm inside the edges), at least
:data:`PLACE_GAP_M` apart: ``locations`` N draws N of them at random
(:func:`choose_locations`), ``locations`` (R, C) lays an R x C grid over the area they cover
(:func:`grid_locations`); each press is solved at every 0.5 N of its loading and a little
beyond its peak (:func:`solve_presses`), so that the mocap, the force log and the static
states all interpolate one solution.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from core.errors import BadInput
from core.progress import progress
from core.protocol import STEP_N, top_level
from sim.twin.indenter import Hand
from sim.twin.mocap_errors import MocapErrors
from sim.twin.phantom import LoadPath, Phantom, PhantomSpec

TRIGGER_EVENT = "Trigger"           # the EVENT label of the sync pulses in the mocap export
# --force-via: its --force-file choices (the first the default)
FORCE_FILES = {"logger": ("csv", "mat"), "analog": ("tsv", "c3d"), "plate": ("tsv",)}
MOCAP_CLOCK = ("analog", "plate")   # the routes the mocap system samples, on its own clock
PRESS_SECONDS = (2.0, 60.0)         # s, the range of --press-seconds
PIVOT_SECONDS = (2.0, 600.0)        # s, the range of --pivot-seconds
RATE_HZ = (10.0, 2000.0)            # Hz, the mocap frame rates a lab runs (--mocap-rate)
MAX_DRIFT_PPM = 1000.0              # |--drift|: beyond it is no clock
MAX_OFFSET_S = 3600.0               # |--offset|: beyond an hour is not plausible
PLACE_GAP_M = 0.015                 # places at least this far apart (sync tells them apart)
PLACES = 5                          # --locations: places drawn at random by default
MAX_GRID_PLACES = 25                # --locations RxC: at most this many places

Lab = Callable[[np.ndarray], np.ndarray]    # phantom-frame points (..., 3) -> lab


@dataclass(frozen=True)
class TwinParams:
    """Everything that shapes a synthetic session."""

    seed: int = 0
    locations: int | tuple[int, int] = PLACES   # N places drawn at random, or a grid (rows, cols)
    repeats: int = 4
    press_seconds: float | None = None   # mean duration of one press cycle (None: ~6 s)
    pivot_seconds: float = 20.0
    rate_hz: float = 500.0               # the mocap's frame rate (--mocap-rate)
    logger_hz: float = 1000.0
    trigger: bool = True
    offset_s: float | None = None        # None: drawn, |offset| in [0.3, 3] s, either sign
    drift_ppm: float | None = None       # None: drawn, |drift| in [10, 60] ppm, either sign
    force_file: str | None = None        # the file session.toml names: csv or mat (logger),
                                         # tsv (QTM analog export) or c3d (analog), tsv (QTM
                                         # force-plate export: plate); None: the route's first
    force_via: str = "logger"            # logger: Speedgoat, own clock; analog: the Nano17
                                         # through the mocap's board; plate: a force plate
    errors: MocapErrors = field(default_factory=MocapErrors)
    phantom: PhantomSpec = field(default_factory=PhantomSpec)

    @property
    def places(self) -> int:
        """How many places are pressed (each ``repeats`` times)."""
        return place_count(self.locations)

    @property
    def force_source(self) -> str:
        """The force file session.toml names (``force_file``, or the route's first)."""
        return self.force_file or FORCE_FILES.get(self.force_via, ("csv",))[0]

    @property
    def on_mocap_clock(self) -> bool:
        """Whether the mocap system samples the force (its analog board, its force plate):
        one clock, a whole number of samples per frame."""
        return self.force_via in MOCAP_CLOCK


def check_params(p: TwinParams) -> None:
    """Refuse parameters no session can have (named by their synth option)."""
    checks = [
        ("--locations", _locations_ok(p.locations),
         f"must be at least 1, or a grid RxC of at most {MAX_GRID_PLACES} places"),
        ("--repeats", p.repeats >= 1, "must be at least 1"),
        ("--force-via", p.force_via in FORCE_FILES, f"must be {' or '.join(FORCE_FILES)}"),
        ("--force-file", p.force_source in FORCE_FILES.get(p.force_via, ()),
         f"must be {' or '.join(FORCE_FILES.get(p.force_via, ()))} with --force-via "
         f"{p.force_via}"),
        ("--mocap-rate", RATE_HZ[0] <= p.rate_hz <= RATE_HZ[1],
         "{:g} Hz: must be between {:g} and {:g} Hz".format(p.rate_hz, *RATE_HZ)),
        ("--mocap-rate", not p.on_mocap_clock or float(p.logger_hz / p.rate_hz).is_integer(),
         f"{p.rate_hz:g} Hz does not divide the {p.logger_hz:g} Hz force rate: sampled by the "
         f"mocap system (--force-via {p.force_via}) the force has a whole number of samples "
         "per frame"),
        ("--offset", not p.on_mocap_clock or (p.offset_s is None and p.drift_ppm is None),
         "--offset and --drift are the logger's clock; sampled by the mocap system "
         f"(--force-via {p.force_via}) there is one"),
        ("--press-seconds", p.press_seconds is None
         or PRESS_SECONDS[0] <= p.press_seconds <= PRESS_SECONDS[1],
         "must be between {:g} and {:g} s".format(*PRESS_SECONDS)),
        ("--pivot-seconds", PIVOT_SECONDS[0] <= p.pivot_seconds <= PIVOT_SECONDS[1],
         "must be between {:g} and {:g} s".format(*PIVOT_SECONDS)),
        ("--drift", p.drift_ppm is None or abs(p.drift_ppm) <= MAX_DRIFT_PPM,
         f"beyond {MAX_DRIFT_PPM:g} ppm is not a clock"),
        ("--offset", p.offset_s is None or abs(p.offset_s) <= MAX_OFFSET_S,
         f"beyond {MAX_OFFSET_S:g} s is not plausible"),
    ]
    for option, ok, what in checks:
        if not ok:
            raise BadInput(option, what)


def place_count(locations: int | tuple[int, int]) -> int:
    """How many places ``locations`` (N, or a grid's (rows, cols)) names."""
    return locations if isinstance(locations, int) else locations[0] * locations[1]


def parse_locations(value: int | str) -> int | tuple[int, int]:
    """``--locations``: a number N of places drawn at random, or ``RxC``, a grid of R rows of
    C places (rows along +x, stacked along +y); anything else, or a grid of more than
    :data:`MAX_GRID_PLACES` places, is refused in one line."""
    if isinstance(value, int):
        locations: int | tuple[int, int] = value
    else:
        grid = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", value)
        number = re.fullmatch(r"\s*(\d+)\s*", value)
        if grid:
            locations = (int(grid[1]), int(grid[2]))
        elif number:
            locations = int(number[1])
        else:
            raise BadInput("--locations", f"{value!r}: must be a number N (places drawn at "
                                          "random) or a grid RxC (e.g. 3x3)")
    if not _locations_ok(locations):
        raise BadInput("--locations", f"{value}: must be at least 1, or a grid RxC of at most "
                                      f"{MAX_GRID_PLACES} places")
    return locations


def _locations_ok(locations: int | tuple[int, int]) -> bool:
    if isinstance(locations, int):
        return locations >= 1
    return min(locations) >= 1 and place_count(locations) <= MAX_GRID_PLACES


def to_lab_frame(to_lab: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Phantom-frame points (..., 3) in the lab, ``to_lab`` a (4, 4) transform."""
    return np.asarray(p) @ to_lab[:3, :3].T + to_lab[:3, 3]


def placement(rng: np.random.Generator) -> np.ndarray:
    """Phantom frame -> lab: turned a little about the vertical, somewhere on the table."""
    yaw = np.radians(rng.uniform(-8.0, 8.0))
    c, s = np.cos(yaw), np.sin(yaw)
    out = np.eye(4)
    out[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    out[:3, 3] = [rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), 0.0]
    return out


def choose_locations(rng: np.random.Generator, phantom: Phantom, n: int,
                      min_gap: float = PLACE_GAP_M) -> np.ndarray:
    """``n`` candidate nodes at least ``min_gap`` apart, in random order."""
    cand = phantom.candidate_locations()
    chosen: list[np.ndarray] = []
    for i in rng.permutation(len(cand)):
        xy = phantom.contact_point(tuple(cand[i]))[:2]
        if all(np.linalg.norm(xy - phantom.contact_point(tuple(c))[:2]) >= min_gap
               for c in chosen):
            chosen.append(cand[i])
        if len(chosen) == n:
            return np.array(chosen)
    raise BadInput("--locations", f"only {len(chosen)} locations fit on the phantom "
                         f"({min_gap * 1e3:.0f} mm apart); asked for {n}")


def grid_locations(phantom: Phantom, rows: int, cols: int,
                   min_gap: float = PLACE_GAP_M) -> np.ndarray:
    """(rows * cols, 2) candidate nodes on a grid, row-major (rows along +x, stacked along
    +y): the grid's points spread evenly over the candidates' extent (its first and last row
    and column on the extent's edges; one alone at its middle), each moved to the nearest
    candidate (a tie to the smaller x, then y: the candidates' order). Refused when two land
    closer than ``min_gap`` (or on one node): the layout leaves too few places for the
    grid."""
    cand = phantom.candidate_locations()
    xy = np.array([phantom.contact_point(tuple(c))[:2] for c in cand])
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    xs = lo[0] + (hi[0] - lo[0]) * _spread(cols)
    ys = lo[1] + (hi[1] - lo[1]) * _spread(rows)
    chosen = []
    for y in ys:
        for x in xs:
            dist = np.round(np.hypot(xy[:, 0] - x, xy[:, 1] - y), 9)   # ties: the first
            chosen.append(int(np.argmin(dist)))                           # (smaller x, then y)
    at = xy[chosen]
    gap = np.linalg.norm(at[:, None] - at[None], axis=2) + np.diag(np.full(len(at), np.inf))
    if gap.min() < min_gap - 1e-9:
        raise BadInput("--locations", f"a {rows}x{cols} grid of places does not fit "
                       f"{min_gap * 1e3:g} mm apart among the {phantom.spec.markers.describe()}"
                       " (a press stays two lattice spacings clear of every marker and 20 mm "
                       "inside the edges); a smaller grid does")
    return cand[chosen]


def _spread(n: int) -> np.ndarray:
    """``n`` fractions of an extent, evenly from 0 to 1 (one alone: 0.5)."""
    return np.array([0.5]) if n == 1 else np.linspace(0.0, 1.0, n)


def force_levels(fmax: float, top: float) -> np.ndarray:
    """Force levels to solve: every 0.5 N up to fmax, 0.25 N, fmax and a margin above it."""
    steps = STEP_N * np.arange(1, top_level(fmax, STEP_N) + 1)
    extra = [f for f in (0.25, fmax, top) if np.all(np.abs(steps - f) > 0.01)]
    return np.unique(np.concatenate([steps, extra]))


def solve_presses(phantom: Phantom, hand: Hand, nodes: np.ndarray,
                   to_lab: np.ndarray) -> list[LoadPath]:
    """The phantom solved along each press of ``hand`` (its direction in the phantom frame)."""
    paths = []
    with progress(range(len(hand.presses)), label="synth: phantom") as bar:
        for k in bar:
            press = hand.presses[k]
            direction = to_lab[:3, :3].T @ press.direction
            levels = force_levels(press.fmax, hand.max_force(k) + 0.01)
            paths.append(phantom.load_path(tuple(nodes[press.location]), direction, levels))
    return paths

"""MSM data drawn from a prior: one pre-training for every lab (domain randomisation).

The cGNN reads a point cloud: nothing in it fixes the marker count, the layout or the
footprint. So instead of fitting the MSM to one lab and sampling it at that lab's markers,
``simulate --prior`` draws each block of examples from a *phantom* drawn from :class:`Prior`
(the spring constants and the contact patch, the footprint, the markers, the press), so that
one network pre-trained on it is a starting point for every lab. The ranges are stated once,
here, each with why; they cover every fit seen so far (the twin's seeds, a 36-marker 12 mm
grid, 20 scattered markers on 150 x 80 mm, the paper's phantom, a Hertzian half-space), and
every draw is kept to presses a lab makes: its centre press at 7.5 N between
:attr:`Prior.depth_m` deep (a draw outside is drawn again, from the same seed: deterministic).

Each block is one phantom: its MSM sized to its footprint (at the paper's spacing, at most
:attr:`Prior.masses` masses a side, so a 160 mm surface costs a 100 mm one), sampled at its
markers with the loaded patch's centre as the last point (:mod:`sim.msm.msm_sampling`), pressed
at ``locations`` places inside its markers, along ``directions`` directions, in 15 steps of
0.5 N. Blocks differ in their marker count: a states file holds them padded to the largest
(:attr:`Prior.markers`), the padding and the occluded markers ``valid`` False, the tip always
last, so a trainer masks what is not there. Block ``b`` is drawn from ``(seed, b)`` alone: a
shard of blocks (``--shard``) draws what a whole run draws, and ``--merge`` joins them to the
same bytes.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, replace
from types import MappingProxyType
from typing import ClassVar

import numpy as np

from core.bounds import Bound, check_ranges
from core.errors import BadInput
from core.protocol import FOOTPRINT_SIDE, STEP_N
from sim.msm import paper
from sim.msm.msm import MSM, MSMParams
from sim.msm.msm_depth import normal_depths
from sim.msm.msm_fit import K_MAX, K_MIN
from sim.msm.msm_grid import PAPER_SPACING_M, grid_params
from sim.msm.msm_protocol import CONTACT_RADIUS, MAX_ANGLE, Plan, Protocol

ATTEMPTS = 200          # draws of one block before the prior is called impossible
PRIOR_LOCATIONS = 4     # places pressed per phantom, by default: its dent seen at a few places
PRIOR_DIRECTIONS = 2    # directions per place: the normal and one within the largest angle


@dataclass(frozen=True)
class Prior:
    """The ranges a pre-training phantom is drawn from (uniform, or log-uniform for the
    springs), each with why."""

    # springs: every fit seen inside: the twin's (159-170 and 6.3-7.7 N/m), scattered:20
    # on 150 x 80 mm (150 and 7.7), the paper's (100 and 21) and a Hertzian half-space of the
    # twin's material (394 and 4.2). No wider: each doubling of room beyond the fits costs
    # the fine-tuned model a few % (docs/results.md, "One pre-training for every lab")
    k_between: tuple[float, float] = (100.0, 420.0)     # N/m, log-uniform
    k_fixed: tuple[float, float] = (4.0, 21.0)          # N/m, log-uniform
    # the tip's patch: one mass (the paper's n_n = 1) to a rounded tip 4 mm across
    contact_radius: tuple[float, float] = (0.0, 0.004)  # m
    # the footprint's sides: palm-sized trainers to the twin's 150 mm blocks
    side: tuple[float, float] = (0.060, 0.160)          # m
    # markers: 12 (the least that spans a dent) to 64 (8 x 8), 8-25 mm apart (3 mm spheres
    # need ~8 mm to be told apart; 25 mm is sparser than any lab seen)
    markers: tuple[int, int] = (12, 64)
    pitch: tuple[float, float] = (0.008, 0.025)         # m
    scattered: float = 0.5                              # share of scattered layouts
    edge: float = 0.005                                 # m: markers this far inside the edge
    # occlusion: a lab's marker is lost in a few % of frames (the twin's 3994 missing of
    # 365k samples is 1 %); up to 8 % of the markers per state
    missing: tuple[float, float] = (0.0, 0.08)
    # the press: a hand stays within ~20 degrees of the normal; up to 30
    max_angle_deg: tuple[float, float] = (0.0, 30.0)
    # how deep the centre press at 7.5 N goes: the twin's 27 mm, the paper's MSM 29.5 mm; a
    # stiffer or softer phantom than either, not deeper than a 40 mm block
    depth_m: tuple[float, float] = (0.010, 0.040)
    masses: int = paper.GRID_N                          # most masses along a side

    # each end of a range, and each single value, within what it can mean
    SPRINGS: ClassVar[Bound] = Bound(K_MIN, K_MAX, unit="N/m", why="the range fit-msm searches")
    BOUNDS: ClassVar[Mapping[str, Bound]] = MappingProxyType({
        "k_between": SPRINGS, "k_fixed": SPRINGS, "contact_radius": CONTACT_RADIUS,
        "side": FOOTPRINT_SIDE,
        "markers": Bound(4, whole=True, why="the fewest a session names"),
        "pitch": Bound(0, min_open=True, unit="m"), "scattered": Bound(0, 1),
        "edge": Bound(0, unit="m"), "missing": Bound(0, 1, max_open=True),
        "max_angle_deg": MAX_ANGLE, "depth_m": Bound(0, unit="m"),
        "masses": Bound(2, whole=True),
    })

    def __post_init__(self) -> None:
        """Refuse, in one line naming the field, a value out of its bound or a range whose
        ends are the wrong way round."""
        check_ranges(self, self.BOUNDS)


PRIOR = Prior()


@dataclass(frozen=True)
class PriorPhantom:
    """One block's phantom: its MSM, its markers at rest (n, 3) and how it is pressed."""

    params: MSMParams
    layout: np.ndarray
    protocol: Protocol
    missing: float          # share of markers occluded per state
    scattered: bool
    pitch: float            # m: the grid's pitch, or the scattered set's least distance


def draw_phantom(prior: Prior, seed: int, block: int, locations: int, directions: int
                 ) -> PriorPhantom:
    """Block ``block``'s phantom, drawn from ``(seed, block)`` until its centre press lies in
    the prior's depth range."""
    rng = np.random.default_rng([seed, block])
    for _ in range(ATTEMPTS):
        phantom = _draw_once(prior, rng, locations, directions)
        if phantom is not None and _depth_ok(prior, phantom):
            return phantom
    raise BadInput(None, f"the prior yields no phantom in {ATTEMPTS} draws (block {block}): "
                         "its ranges contradict each other")


def _draw_once(prior: Prior, rng: np.random.Generator, locations: int, directions: int
               ) -> PriorPhantom | None:
    """One draw (None: its markers do not fit its footprint, or too few of them)."""
    size = tuple(rng.uniform(*prior.side, size=2))
    spacing = max(PAPER_SPACING_M, max(size) / (prior.masses - 1))
    params = replace(grid_params(size, spacing),
                     k_between=log_uniform(rng, prior.k_between),
                     k_fixed=log_uniform(rng, prior.k_fixed))
    scattered = bool(rng.random() < prior.scattered)
    pitch = rng.uniform(*prior.pitch)
    layout = draw_layout(rng, np.array(size), pitch, scattered, prior.markers, prior.edge)
    if layout is None or len(layout) < prior.markers[0]:
        return None
    protocol = Protocol(locations=locations, directions=directions,
                        steps=int(round(paper.FMAX_N / STEP_N)), fmax=paper.FMAX_N,
                        max_angle_deg=rng.uniform(*prior.max_angle_deg),
                        seed=int(rng.integers(2**31)),
                        contact_radius=rng.uniform(*prior.contact_radius))
    return PriorPhantom(params, layout, protocol, rng.uniform(*prior.missing), scattered, pitch)


def draw_layout(rng: np.random.Generator, size: np.ndarray, pitch: float, scattered: bool,
                markers: tuple[int, int], edge: float) -> np.ndarray | None:
    """Markers (n, 3) at z = 0 on a footprint of ``size`` (m), ``edge`` inside it, their count
    in ``markers``: scattered at least ``pitch`` apart, or a grid of ``pitch`` (None: none
    fits). The MSM's prior and the moulds' (:mod:`sim.msm.mould_prior`) draw them alike."""
    return (_scattered if scattered else _grid)(rng, size, pitch, markers, edge)


def _grid(rng: np.random.Generator, size: np.ndarray, pitch: float, markers: tuple[int, int],
          edge: float) -> np.ndarray | None:
    """A rows x columns grid of ``pitch`` with a count in ``markers``, placed at random
    inside the footprint (None: it does not fit)."""
    room = size - 2 * edge
    most = np.floor(room / pitch + 1e-9).astype(int) + 1          # columns, rows that fit
    lo, hi = markers
    shapes = [(c, r) for c in range(2, most[0] + 1) for r in range(2, most[1] + 1)
              if lo <= c * r <= hi]
    if not shapes:
        return None
    cols, rows = shapes[int(rng.integers(len(shapes)))]
    extent = np.array([cols - 1, rows - 1]) * pitch
    corner = edge + rng.uniform(0, 1, 2) * (room - extent)
    x, y = np.meshgrid(np.arange(cols) * pitch, np.arange(rows) * pitch)
    xy = np.column_stack([x.ravel(), y.ravel()]) + corner
    return np.column_stack([xy, np.zeros(len(xy))])


def _scattered(rng: np.random.Generator, size: np.ndarray, pitch: float,
               markers: tuple[int, int], edge: float) -> np.ndarray | None:
    """A count in ``markers`` of points at least ``pitch`` apart, uniform inside the
    footprint (as many as fit in a bounded number of tries)."""
    want = int(rng.integers(markers[0], markers[1] + 1))
    points: list[np.ndarray] = []
    for _ in range(40 * want):
        p = edge + rng.uniform(0, 1, 2) * (size - 2 * edge)
        if all(np.hypot(*(p - q)) >= pitch for q in points):
            points.append(p)
            if len(points) == want:
                break
    if not points:
        return None
    xy = np.array(points)
    return np.column_stack([xy, np.zeros(len(xy))])


def _depth_ok(prior: Prior, phantom: PriorPhantom) -> bool:
    """Whether the normal press at 7.5 N on the mass nearest the markers' centre goes as deep
    as the prior allows."""
    model = MSM(phantom.params)
    centre = phantom.layout[:, :2].mean(axis=0)
    node = int(np.argmin(np.linalg.norm(model.rest[:, :2] - centre, axis=1)))
    plan = Plan(phantom.protocol, np.array([node]), np.array([[[0.0, 0.0, -1.0]]]),
                np.zeros((1, 0, 2), np.int64))
    depth = float(normal_depths(plan, phantom.params, np.array([0]))[0])
    return prior.depth_m[0] <= depth <= prior.depth_m[1]


def log_uniform(rng: np.random.Generator, span: tuple[float, float]) -> float:
    """A draw uniform in the logarithm between the ends of ``span``."""
    return float(np.exp(rng.uniform(np.log(span[0]), np.log(span[1]))))


def prior_record(prior: Prior) -> dict:
    """The prior as JSON values (the states file's ``prior`` attribute)."""
    return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(prior).items()}

"""The paper's MSM data-generation protocol: what to simulate, every random choice drawn up front.

Protocol (paper, "Data generation"): ``locations`` masses drawn at random without replacement;
at each, ``directions`` force directions (the normal, pointing into the surface, plus random
directions up to 45 degrees from it, uniform on that spherical cap); along each, the force on
that one mass grows to ``fmax`` in ``steps`` equal steps, ``F_t = t fmax / steps``. Every random
choice is drawn up front from ``seed``, so a shard draws the same plan as a full run.

Shards (``shard=(i, count)``, i from 0) simulate a contiguous block of locations
(``np.array_split``); :mod:`sim.msm.msm_shards` joins them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from core.bounds import Bound
from core.errors import BadInput
from sim.cone import cone_directions
from sim.msm import paper

MULTI_PER_SEQUENCE = 15
MAX_ANGLE_RANGE_DEG = (0.0, 90.0)   # a force direction's angle from the normal: into the surface
CONTACT_RADIUS_LIMIT_M = 0.05       # m, excluded: a patch this wide covers the paper's surface
MAX_ANGLE = Bound(*MAX_ANGLE_RANGE_DEG, unit="deg")
CONTACT_RADIUS = Bound(0, CONTACT_RADIUS_LIMIT_M, max_open=True, unit="m")


@dataclass(frozen=True)
class Protocol:
    """What to simulate: the paper's defaults."""

    locations: int = paper.LOCATIONS
    directions: int = paper.DIRECTIONS
    steps: int = paper.STEPS
    fmax: float = paper.FMAX_N
    max_angle_deg: float = paper.MAX_ANGLE_DEG
    seed: int = 0
    contact_radius: float = 0.0     # m: the load is shared by the masses this close (n_n)

    def check(self, n_masses: int) -> None:
        """Refuse a protocol that cannot be simulated (one line naming the parameter)."""
        for name in ("locations", "directions", "steps"):
            if getattr(self, name) < 1:
                raise BadInput(None, f"--{name} must be at least 1, got {getattr(self, name)}")
        if self.locations > n_masses:
            raise BadInput(None, f"--locations {self.locations} exceeds the {n_masses} masses")
        if not (math.isfinite(self.fmax) and self.fmax > 0):
            raise BadInput(None, f"--fmax must be a finite positive force, got {self.fmax}")
        MAX_ANGLE.check("max_angle_deg", self.max_angle_deg)
        CONTACT_RADIUS.check("contact_radius", self.contact_radius)

    @property
    def step_n(self) -> float:
        """The force step (N): the states' level spacing."""
        return self.fmax / self.steps

    @property
    def sequences(self) -> int:
        return self.locations * self.directions

    @property
    def multi_per_sequence(self) -> int:
        pairs = (self.steps + 1) * self.steps // 2 - self.steps   # end - start >= 2
        return min(MULTI_PER_SEQUENCE, pairs)


@dataclass(frozen=True)
class Plan:
    """Every random choice of a protocol."""

    protocol: Protocol
    nodes: np.ndarray        # (L,) loaded mass of each location
    directions: np.ndarray   # (L, D, 3) unit force directions; [:, 0] is the normal (0, 0, -1)
    multi: np.ndarray        # (L * D, M, 2) multi-step (start, end) steps of each sequence


def draw_plan(protocol: Protocol, n_masses: int, candidates: np.ndarray | None = None) -> Plan:
    """Draw locations (among ``candidates``, default every mass), directions and multi-step
    pairs from ``protocol.seed``."""
    candidates = np.arange(n_masses) if candidates is None else np.asarray(candidates)
    protocol.check(len(candidates))
    p = protocol
    rng = np.random.default_rng(p.seed)
    nodes = candidates[rng.choice(len(candidates), size=p.locations, replace=False)]
    dirs = np.empty((p.locations, p.directions, 3))
    dirs[:, 0] = (0.0, 0.0, -1.0)
    dirs[:, 1:] = cone_directions(rng, p.max_angle_deg, (p.locations, p.directions - 1))
    pairs = np.array([(s, e) for s in range(p.steps + 1) for e in range(s + 2, p.steps + 1)],
                     dtype=np.int64).reshape(-1, 2)
    multi = np.empty((p.sequences, p.multi_per_sequence, 2), dtype=np.int64)
    for s in range(p.sequences):
        pick = np.sort(rng.choice(len(pairs), size=p.multi_per_sequence, replace=False))
        multi[s] = pairs[pick]
    return Plan(p, nodes.astype(np.int64), dirs, multi)


def shard_locations(locations: int, shard: tuple[int, int] | None) -> np.ndarray:
    """The contiguous block of location indices of shard (i, count), or all of them."""
    if shard is None:
        return np.arange(locations)
    i, count = shard
    if not (0 <= i < count) or count > locations:
        raise BadInput(None, f"--shard {i}/{count}: need 0 <= I < N <= locations ({locations})")
    return np.array_split(np.arange(locations), count)[i]


def parse_shard(text: str) -> tuple[int, int]:
    """``"I/N"`` -> (I, N), block I (from 0) of N; that N does not exceed the locations is
    :func:`shard_locations`' check."""
    try:
        i, count = (int(v) for v in text.split("/"))
    except ValueError:
        raise BadInput(None, f"--shard must look like I/N (e.g. 0/4), got {text!r}") from None
    if not 0 <= i < count:
        raise BadInput(None, f"--shard {i}/{count}: need 0 <= I < N")
    return i, count

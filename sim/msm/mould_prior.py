"""Curved phantoms drawn from a prior over moulds, for the solid model to press: the
pre-training of the generic model for curved labs (``simulate --prior N --moulds``).

The MSM's prior (:mod:`sim.msm.msm_prior`) draws flat surfaces; a model pre-trained on them
predicts a flat block's dent about the vertical on a dome, where the cap moves twice as much
and along its normal (docs/results.md, "Curved phantoms"). A spring surface cannot say how a
cap's height changes what it gives; the solid model (:mod:`sim.solid`) can, so the curved
prior draws moulds and presses their solids. Each block is one phantom:

- its mould: a block ``thickness`` deep below its rim (z = 0: the footprint's corners under a
  dome, the two edges a ridge meets) under a cap ``height`` high (no higher than a
  half-sphere or a half-cylinder over the footprint), a *dome* (the sphere through the
  footprint's corners, as the twin's ``dome:HEIGHT``) or a *ridge* (the cylinder through two
  opposite edges, along x or y: a limb, an abdomen's curved slab; :class:`Cap`), meshed as
  the solid meshes any mould (5 mm across, 8 layers);
- its material: how deep the centre press at 7.5 N goes (the MSM prior's range), which sets
  the modulus once the stiffening, its reach and the tip's patch are drawn (the fits on the
  twins' flat and domed blocks lie inside each range);
- its markers: the MSM prior's layouts (a grid or scattered, the same counts and pitches)
  over the footprint, each resting straight above the cap by a marker's radius;
- its presses: ``locations`` places among the top face's nodes clear of the markers,
  ``directions`` directions each within a hand's angle of the place's inward normal, 15 steps
  of 0.5 N (as the lab's solid is pressed: :mod:`sim.solid.solid_dataset`).

Block ``b`` is drawn from ``(seed, b)`` alone, as the MSM prior's are.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from enum import StrEnum
from types import MappingProxyType
from typing import ClassVar

import numpy as np

from core.bounds import Bound, check_ranges
from core.errors import BadInput
from core.protocol import STEP_N
from data_schema.shape import Shape, heightfield_solid, quad_triangles, shape_from_mesh
from sim.msm import paper
from sim.msm.msm_prior import ATTEMPTS, PRIOR, draw_layout, log_uniform
from sim.msm.msm_protocol import MAX_ANGLE, Plan, Protocol, draw_plan
from sim.solid.block_mesh import BlockGeometry
from sim.solid.fit_solid_params import FitSolidParams
from sim.solid.solid_dataset import candidate_places
from sim.solid.solid_fit import SolidMaterial
from sim.solid.solid_model import CONTACT_RADIUS, REACH, Attachments, SolidModel

SPACING_M = 5e-3        # the solid's default mesh (fit-solid's): 5 mm across ...
LAYERS = 8              # ... and 8 layers through
CAP_GRID = 41           # the mould's surface: this many vertices a side


class Cap(StrEnum):
    """The mould's top: a dome (a spherical cap) or a ridge (a cylindrical one) along x or y."""

    DOME = "dome"
    RIDGE_X = "ridge along x"
    RIDGE_Y = "ridge along y"


@dataclass(frozen=True)
class MouldPrior:
    """The ranges a curved pre-training phantom is drawn from (uniform, or log-uniform for the
    stiffening), each with why."""

    # the cap above the rim: a 5 mm bump to a cap 50 mm high (the dome twin's 30 mm, a
    # forearm's 40 mm half-width); the block under the rim: a thin shell to the twin's 32 mm
    height: tuple[float, float] = (0.005, 0.050)       # m
    thickness: tuple[float, float] = (0.015, 0.040)    # m
    ridge_share: float = 0.5                           # the rest are domes
    side: tuple[float, float] = PRIOR.side             # m: as the MSM prior's footprints
    # the centre press at 7.5 N: as deep as the MSM prior's, and never through the column
    depth_m: tuple[float, float] = PRIOR.depth_m
    column_share: float = 0.8                          # of the column under the centre
    # the solid's stiffening and its reach (fits: 300-1000 1/m^2, 1-8 mm), and the tip's
    # patch (fits: 6.6-8.5 mm with the nodal shares, 3.8-4.0 with the integrated load; a
    # rounded tip 3 mm across to a finger's pad)
    stiffening: tuple[float, float] = (100.0, 1000.0)  # 1/m^2, log-uniform
    reach: tuple[float, float] = (0.001, 0.010)        # m
    contact_radius: tuple[float, float] = (0.003, 0.009)  # m
    marker_height: tuple[float, float] = (0.001, 0.003)   # m: a marker's radius
    max_angle_deg: tuple[float, float] = PRIOR.max_angle_deg

    BOUNDS: ClassVar[Mapping[str, Bound]] = MappingProxyType({
        "height": Bound(0, 0.2, min_open=True, unit="m"),
        "thickness": Bound(0, 0.2, min_open=True, unit="m"),
        "ridge_share": Bound(0, 1), "side": PRIOR.BOUNDS["side"],
        "depth_m": Bound(0, unit="m", min_open=True), "column_share": Bound(0, 1, min_open=True),
        "stiffening": Bound(0, 1e6, min_open=True, unit="1/m^2"), "reach": REACH,
        "contact_radius": CONTACT_RADIUS, "marker_height": Bound(0, 0.01, unit="m"),
        "max_angle_deg": MAX_ANGLE,
    })

    def __post_init__(self) -> None:
        """Refuse, in one line naming the field, a value out of its bound or a range whose
        ends are the wrong way round."""
        check_ranges(self, self.BOUNDS)


MOULDS = MouldPrior()


@dataclass(frozen=True)
class MouldPhantom:
    """One block's phantom: its cap and solid, its markers at rest (n, 3), its plan of presses
    at ``places`` (L, 3), the material but the modulus, and how deep its centre press at
    7.5 N goes (``depth`` at ``centre``: the modulus follows, :func:`modulus_for_depth`)."""

    cap: Cap
    height: float
    thickness: float
    model: SolidModel
    layout: np.ndarray
    plan: Plan
    places: np.ndarray
    centre: np.ndarray
    depth: float
    stiffening: float
    reach: float
    missing: float
    scattered: bool
    pitch: float

    def material(self, modulus: float) -> SolidMaterial:
        """Its material at ``modulus`` (Pa)."""
        return SolidMaterial(modulus=modulus, stiffening=self.stiffening,
                             poisson=FitSolidParams.poisson,
                             contact_radius=self.plan.protocol.contact_radius, reach=self.reach)

    def at(self) -> Attachments:
        """Where the markers ride on the cap."""
        return Attachments.riding(self.layout, self.model.block.top(self.layout[:, :2]))


def cap_span(cap: Cap, size: tuple[float, float]) -> tuple[float, list[int]]:
    """Half the cap's span over the footprint ``size`` (m) (from the middle to the corners, or
    to the two edges a ridge meets) and the axes it curves along."""
    length, width = size
    if cap is Cap.DOME:
        return float(np.hypot(length, width)) / 2, [0, 1]
    return (width / 2, [1]) if cap is Cap.RIDGE_X else (length / 2, [0])


def cap_top(cap: Cap, size: tuple[float, float], height: float
            ) -> Callable[[np.ndarray], np.ndarray]:
    """The cap's height above the rim over (P, 2) points of the footprint ``size`` (m): a
    sphere through its corners, or a cylinder (along x or y) through two opposite edges,
    ``height`` above the rim at the middle; no higher than its half-span (a half-sphere or a
    half-cylinder: higher, the surface through those edges would rise as walls)."""
    half, axes = cap_span(cap, size)
    if height > half:
        raise ValueError(f"a cap {height} m high over a half-span of {half} m is no cap")
    centre = np.array([size[0] / 2, size[1] / 2])
    radius = (half ** 2 + height ** 2) / (2 * height)

    def top(xy: np.ndarray) -> np.ndarray:
        r2 = ((xy[:, axes] - centre[axes]) ** 2).sum(axis=1)
        return np.sqrt(np.maximum(radius ** 2 - r2, 0.0)) - (radius - height)

    return top


def cap_surface(cap: Cap, size: tuple[float, float], height: float, n: int = 21
                ) -> tuple[np.ndarray, np.ndarray]:
    """The cap at rest as an ``n`` x ``n`` grid of vertices (n^2, 3) m and its triangles: what
    the simulate recording draws under a mould's markers."""
    gx, gy = np.meshgrid(np.linspace(0, size[0], n), np.linspace(0, size[1], n), indexing="ij")
    xy = np.c_[gx.ravel(), gy.ravel()]
    idx = np.arange(n * n).reshape(n, n)
    quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], -1)
    return np.c_[xy, cap_top(cap, size, height)(xy)], quad_triangles(quads.reshape(-1, 4))


def mould_shape(top: Callable[[np.ndarray], np.ndarray], size: tuple[float, float],
                thickness: float) -> Shape:
    """The closed mould: ``top`` over the footprint, the table ``thickness`` below the rim."""
    xs, ys = np.linspace(0, size[0], CAP_GRID), np.linspace(0, size[1], CAP_GRID)
    return shape_from_mesh(heightfield_solid(xs, ys, top, -thickness), "the prior's mould")


def draw_mould(prior: MouldPrior, seed: int, block: int, locations: int, directions: int
               ) -> MouldPhantom:
    """Block ``block``'s phantom, drawn from ``(seed, block)`` (a draw whose markers do not
    fit, or whose block has too few places to press, is drawn again)."""
    rng = np.random.default_rng([seed, block])
    for _ in range(ATTEMPTS):
        phantom = _draw_once(prior, rng, locations, directions)
        if phantom is not None:
            return phantom
    raise BadInput(None, f"the prior over moulds yields no phantom in {ATTEMPTS} draws "
                         f"(block {block}): its ranges contradict each other")


def _draw_once(prior: MouldPrior, rng: np.random.Generator, locations: int, directions: int
               ) -> MouldPhantom | None:
    """One draw (None: a cap higher than its half-span, markers that do not fit, or fewer
    places than ``locations``)."""
    size = (float(rng.uniform(*prior.side)), float(rng.uniform(*prior.side)))
    ridge = bool(rng.random() < prior.ridge_share)
    height, thickness = float(rng.uniform(*prior.height)), float(rng.uniform(*prior.thickness))
    along_x = bool(rng.random() < 0.5)                  # a ridge's axis (drawn for a dome too)
    cap = (Cap.RIDGE_X if along_x else Cap.RIDGE_Y) if ridge else Cap.DOME
    if height > cap_span(cap, size)[0]:
        return None                                     # higher than a half-cylinder
    top = cap_top(cap, size, height)
    scattered, pitch = bool(rng.random() < PRIOR.scattered), float(rng.uniform(*PRIOR.pitch))
    flat = draw_layout(rng, np.array(size), pitch, scattered, PRIOR.markers, PRIOR.edge)
    if flat is None or len(flat) < PRIOR.markers[0]:
        return None
    layout = np.c_[flat[:, :2], top(flat[:, :2]) + rng.uniform(*prior.marker_height)]
    contact = float(rng.uniform(*prior.contact_radius))
    protocol = Protocol(locations=locations, directions=directions,
                        steps=int(round(paper.FMAX_N / STEP_N)), fmax=paper.FMAX_N,
                        max_angle_deg=float(rng.uniform(*prior.max_angle_deg)),
                        seed=int(rng.integers(2**31)), contact_radius=contact)
    stiffening, reach = log_uniform(rng, prior.stiffening), float(rng.uniform(*prior.reach))
    depth, missing = float(rng.uniform(*prior.depth_m)), float(rng.uniform(*PRIOR.missing))
    block = BlockGeometry(size, thickness, 0.0, mould_shape(top, size, thickness))
    model = SolidModel(block, SPACING_M, LAYERS)
    try:
        candidates = candidate_places(model, layout, contact)
    except BadInput:                                    # no node clear of the markers
        return None
    if len(candidates) < locations:
        return None
    plan = draw_plan(protocol, len(candidates), np.arange(len(candidates)))
    centre = _centre_place(candidates, layout)
    column = float(model.block.top(centre[None, :2])[0]) + thickness
    return MouldPhantom(cap, height, thickness, model, layout, plan, candidates[plan.nodes],
                        centre, min(depth, prior.column_share * column), stiffening, reach,
                        missing, scattered, pitch)


def _centre_place(candidates: np.ndarray, layout: np.ndarray) -> np.ndarray:
    """The candidate place nearest the markers' centre (x, y)."""
    centre = layout[:, :2].mean(axis=0)
    return candidates[int(np.argmin(np.linalg.norm(candidates[:, :2] - centre, axis=1)))]


def modulus_for_depth(tip_per_newton: float, depth: float, stiffening: float,
                      force: float = paper.FMAX_N) -> float:
    """The modulus (Pa) at which a press whose linear tip moves ``tip_per_newton`` (m/N at
    unit modulus) goes ``depth`` (m) deep at ``force`` (N) under the stiffening law
    (``d + s d^3 = d_lin``: :func:`sim.solid.solid_model.stiffened`)."""
    return force * tip_per_newton / (depth + stiffening * depth ** 3)


def mould_record(prior: MouldPrior) -> dict:
    """The prior as JSON values (the states file's ``prior`` attribute)."""
    return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(prior).items()}

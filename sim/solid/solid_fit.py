"""The solid fitted to a lab's presses: the block's modulus, how it stiffens, its Poisson ratio
and each ``"fit"`` label's stiffness ratio, each with its uncertainty.

The distance minimised is every point's (the markers and the tip) predicted position against
the measured one, at every loaded state of the presses given, the tip's squared error
weighed as much as the markers' together (:func:`weighted`). Each press's prediction is its
own rest plus the solid's displacement, so a marker's rest noise is not fitted. The modulus
scales every unit response (no new solve), and the stiffening maps each state's size (no new
solve); the Poisson ratio and the labels' ratios change the stiffness, so a new one is
factorised, and the contact radius changes the loads, so each place is solved again (the last
material's factorisation and responses are kept: :class:`Responses`).

Uncertainty: a sandwich estimate with the presses as clusters (the states of one press are not
independent), at the optimum, carried to each parameter by its Jacobian.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from core.bounds import Bound
from sim.solid.elasticity import POISSON
from sim.solid.measured_presses import MeasuredSet
from sim.solid.solid_model import (
    CONTACT_RADIUS,
    REACH,
    PlaceResponse,
    Probes,
    SolidModel,
    predict,
)

STIFFENING_FIT = (1e-2, 1e6)   # 1/m^2: from linear to a wall at 1 mm
RATIO_FIT = (0.1, 20.0)     # a fitted label's ratio stays in the interior's accepted range
PATCH_SPACINGS = (0.4, 4.0)    # the contact radius is fitted within these mesh spacings


@dataclass(frozen=True)
class SolidMaterial:
    """What the solid is made of: modulus (Pa), stiffening (1/m^2), Poisson ratio, and the
    stiffness ratio of each label to the block's (label 0 is the block: 1)."""

    modulus: float
    stiffening: float
    poisson: float
    ratios: tuple[float, ...] = (1.0,)
    contact_radius: float = 0.005   # m: the tip's patch (solid_model)
    reach: float = 0.5              # m: how far from the tip the stiffening reaches


@dataclass
class SolidFit:
    """A fitted material, its uncertainties (one sd) and the distances it leaves."""

    material: SolidMaterial
    sd: dict[str, float]
    marker_mm: float           # mean distance of the markers' predictions (mm)
    tip_mm: float              # mean distance of the tip's (mm)
    all_mm: float              # of every point, markers and tip (as fit-msm's distance)
    still_mm: float            # the markers' mean distance to their rest: a still surface
    per_marker_mm: np.ndarray  # (P,) each marker's mean distance
    per_press_mm: np.ndarray   # (presses,) each press's mean distance, every point
    evaluations: int
    factorisations: int


@dataclass
class Responses:
    """Each press's unit responses for the last material asked for, and its factorisation:
    kept until the Poisson ratio, a label's ratio or the contact radius changes."""

    model: SolidModel
    fractions: np.ndarray                   # (E, labels) each element's share of each label
    solvers: dict = field(default_factory=dict)
    places: dict = field(default_factory=dict)
    probes: Probes | None = None
    factorisations: int = 0

    def at(self, data: MeasuredSet, m: SolidMaterial) -> list[PlaceResponse]:
        """Each press's unit response for the material's Poisson ratio, labels' ratios and
        contact radius (a new material is factorised; a new radius is solved again)."""
        key = (round(m.poisson, 12), tuple(round(r, 12) for r in m.ratios))
        if key not in self.solvers:
            modulus = self.fractions @ np.asarray(m.ratios, dtype=np.float64)
            self.solvers = {key: self.model.factorise(modulus, m.poisson)}
            self.factorisations += 1
        full = (key, round(m.contact_radius, 12))
        if full not in self.places:
            if self.probes is None:
                self.probes = self.model.probes(data.attachments())
            places, which = data.places()
            found = self.model.respond(self.solvers[key], places, m.contact_radius,
                                       self.probes)
            self.places = {full: [found[i] for i in which]}
        return self.places[full]


def residuals(data: MeasuredSet, responses: Sequence[PlaceResponse], material: SolidMaterial
              ) -> list[np.ndarray]:
    """Per press: (T, P + 1, 3) predicted minus measured (0 where the measurement is missing)."""
    at = data.attachments()
    out = []
    for press, resp in zip(data.presses, responses, strict=True):
        loads = np.vstack([np.zeros(3), press.loads(resp.tip)])
        pts, tip = predict(resp, loads, material.modulus, material.stiffening, material.reach,
                           at)
        moved = np.concatenate([pts, tip[:, None]], axis=1)
        pred = press.rest[None] + (moved[1:] - moved[:1])
        diff = pred - press.states
        out.append(np.where(np.isfinite(diff), diff, 0.0))
    return out


def weighted(residual: np.ndarray) -> np.ndarray:
    """(T, P + 1, 3) a press's residuals as the fit weighs them: the tip's squared error counts
    as much as the markers' together (where the press's stiffness shows: how deep the tip
    sinks under its force; fit-msm --map weighs it alike)."""
    out = residual.copy()
    out[:, -1] *= np.sqrt(residual.shape[1] - 1)
    return out


@dataclass(frozen=True)
class Coordinates:
    """How a material is laid out for the least squares: the logarithms of the modulus, the
    stiffening, the contact radius, the reach and the fitted labels' ratios, and the Poisson
    ratio itself where it is fitted; with their bounds."""

    start: SolidMaterial
    labels: tuple[int, ...]           # the labels whose ratio is fitted
    poisson: bool                     # whether the Poisson ratio is fitted
    spacing: float                    # m, the mesh's: the contact radius stays above it
    reach: bool = True                # whether the reach is fitted (else held at the start's)

    @property
    def names(self) -> list[str]:
        return ["modulus", "stiffening", "contact_radius"] + (["reach"] if self.reach else []) \
            + (["poisson"] if self.poisson else []) + [f"ratio_{k}" for k in self.labels]

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(low, high): the contact radius stays within :data:`PATCH_SPACINGS` mesh spacings,
        at least 2 mm at the default 5 mm: the top facets' quadrature points lie 1 mm apart, and
        a patch that holds only a few of them loads the mesh as a point would, whatever its
        radius (a flat objective). The integrated load needs no more: the bound of the nodal
        shares (1.01 spacings) held the fits at 5.05 mm, 0.36 mm from a lump twin's markers
        against 0.31 at 3.8 mm."""
        radius_min, radius_max = _limits(CONTACT_RADIUS)
        reach_min, reach_max = _limits(REACH)
        radius = (max(radius_min, PATCH_SPACINGS[0] * self.spacing),
                  max(radius_max, PATCH_SPACINGS[1] * self.spacing))
        pairs = [(-np.inf, np.inf), tuple(np.log(STIFFENING_FIT)), tuple(np.log(radius))] + \
            ([(np.log(reach_min), np.log(reach_max))] if self.reach else []) + \
            ([_limits(POISSON)] if self.poisson else []) + \
            [tuple(np.log(RATIO_FIT))] * len(self.labels)
        return np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])

    def pack(self, m: SolidMaterial) -> np.ndarray:
        x = [np.log(m.modulus), np.log(m.stiffening), np.log(m.contact_radius)] + \
            ([np.log(m.reach)] if self.reach else []) + \
            ([m.poisson] if self.poisson else []) + [np.log(m.ratios[k]) for k in self.labels]
        lo, hi = self.bounds()
        return np.clip(np.array(x, dtype=np.float64), lo + 1e-9, hi - 1e-9)

    def unpack(self, x: np.ndarray) -> SolidMaterial:
        ratios = list(self.start.ratios)
        for k, v in zip(self.labels, x[len(x) - len(self.labels):], strict=True):
            ratios[k] = float(np.exp(v))
        rest = list(x[3:])
        reach = float(np.exp(rest.pop(0))) if self.reach else self.start.reach
        poisson = float(rest.pop(0)) if self.poisson else self.start.poisson
        return SolidMaterial(modulus=float(np.exp(x[0])), stiffening=float(np.exp(x[1])),
                             contact_radius=float(np.exp(x[2])), reach=reach, poisson=poisson,
                             ratios=tuple(ratios))


def _limits(bound: Bound) -> tuple[float, float]:
    """A bound's (min, max): both are stated for the settings fitted here."""
    if bound.min is None or bound.max is None:
        raise ValueError(f"{bound} lacks a limit")
    return bound.min, bound.max


def fit_solid(data: MeasuredSet, responses: Responses, fit_labels: Sequence[int],
              start: SolidMaterial, fit_poisson: bool = False) -> SolidFit:
    """Least squares over the modulus, the stiffening, the contact radius, the reach, the
    Poisson ratio (``fit_poisson``) and the ratios of ``fit_labels``, from ``start``: first
    with the reach held at the start's, then everything from there (the reach alone, from a
    material far from the data, wanders to a bound where the tip's stiffening stands in for
    the rest)."""
    held = Coordinates(start, tuple(fit_labels), fit_poisson, responses.model.spacing,
                       reach=False)
    first = _least_squares(data, responses, held, start)
    coords = Coordinates(held.unpack(first.x), tuple(fit_labels), fit_poisson,
                         responses.model.spacing)
    sol = _least_squares(data, responses, coords, coords.start)
    material = coords.unpack(sol.x)
    per_press = residuals(data, responses.at(data, material), material)
    sd = _uncertainty(sol, per_press, coords.names)
    return _scored(data, per_press, material, sd, first.nfev + sol.nfev,
                   responses.factorisations)


def _least_squares(data: MeasuredSet, responses: Responses, coords: Coordinates,
                   start: SolidMaterial) -> Any:
    """One bounded least squares over ``coords`` from ``start`` (scipy's OptimizeResult)."""
    def fun(x: np.ndarray) -> np.ndarray:
        m = coords.unpack(x)
        return np.concatenate([weighted(r).ravel() for r in
                               residuals(data, responses.at(data, m), m)])

    return least_squares(fun, coords.pack(start), bounds=coords.bounds(), diff_step=1e-3,
                         x_scale=1.0, xtol=1e-8, ftol=1e-10, gtol=1e-10)


def _uncertainty(sol: Any, per_press: list[np.ndarray], names: list[str]
                 ) -> dict[str, float]:
    """One sd per parameter: the press-clustered sandwich on the fitted coordinates, carried
    to the parameters (all but the Poisson ratio are fitted as logarithms)."""
    jac = np.asarray(sol.jac)
    bread = np.linalg.pinv(jac.T @ jac)
    meat = np.zeros_like(bread)
    start = 0
    for r in per_press:
        n = r.size
        g = jac[start:start + n].T @ weighted(r).ravel()
        meat += np.outer(g, g)
        start += n
    cov = bread @ meat @ bread
    sd_x = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    x = np.asarray(sol.x)
    out = {}
    for i, name in enumerate(names):
        out[name] = float(sd_x[i] if name == "poisson" else np.exp(x[i]) * sd_x[i])
    return out


def _scored(data: MeasuredSet, per_press: list[np.ndarray], material: SolidMaterial,
            sd: dict[str, float], evaluations: int, factorisations: int) -> SolidFit:
    """The distances the fit leaves, beside a still surface's."""
    dist = [np.linalg.norm(r, axis=-1) for r in per_press]              # (T, P + 1)
    still = [np.linalg.norm(p.states[:, :-1] - p.rest[None, :-1], axis=-1) for p in data.presses]
    valid = [np.isfinite(p.states).all(axis=-1) for p in data.presses]
    d = np.concatenate(dist)
    ok = np.concatenate(valid)
    markers, tips = d[:, :-1], d[:, -1]
    ok_m, ok_t = ok[:, :-1], ok[:, -1]
    s = np.concatenate(still)
    per_marker = np.array([markers[ok_m[:, j], j].mean() for j in range(markers.shape[1])])
    press_mm = np.array([di[ok_i].mean() for di, ok_i in zip(dist, valid, strict=True)])
    return SolidFit(material=material, sd=sd, marker_mm=float(markers[ok_m].mean() * 1e3),
                    tip_mm=float(tips[ok_t].mean() * 1e3), all_mm=float(d[ok].mean() * 1e3),
                    still_mm=float(np.nanmean(np.where(ok_m, s, np.nan)) * 1e3),
                    per_marker_mm=per_marker * 1e3, per_press_mm=press_mm * 1e3,
                    evaluations=evaluations,
                    factorisations=factorisations)

"""The solid fitted to a lab's presses: the block's modulus, how it stiffens, its Poisson ratio
and each ``"fit"`` label's stiffness ratio, each with its uncertainty.

The distance minimised is every point's (the markers and the tip) predicted position against
the measured one, at every loaded state of the presses given, the tip's squared error
weighed as much as the markers' together (:func:`weighted`). Each press's prediction is its
own rest plus the solid's displacement, so a marker's rest noise is not fitted. The modulus
scales every unit response (no new solve), and the stiffening maps each state's size (no new
solve); the Poisson ratio and the labels' ratios change the stiffness, so a new one is
factorised (each distinct material once: a small cache).

Uncertainty: a sandwich estimate with the presses as clusters (the states of one press are not
independent), at the optimum, carried to each parameter by its Jacobian.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

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
PATCH_SPACINGS = (1.01, 4.0)   # the contact radius is fitted within these mesh spacings


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
    """Unit responses per place for one material's stiffness (cached by what changes it)."""

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


def fit_solid(data: MeasuredSet, responses: Responses, fit_labels: Sequence[int],
              start: SolidMaterial, fit_poisson: bool = True) -> SolidFit:
    """Least squares over the modulus, the stiffening, the Poisson ratio (``fit_poisson``)
    and the ratios of ``fit_labels``, from ``start``."""
    names = ["modulus", "stiffening", "contact_radius", "reach"] + \
        (["poisson"] if fit_poisson else []) + [f"ratio_{k}" for k in fit_labels]
    evaluations = 0

    def unpack(x: np.ndarray) -> SolidMaterial:
        ratios = list(start.ratios)
        for k, v in zip(fit_labels, x[len(x) - len(fit_labels):], strict=True):
            ratios[k] = float(np.exp(v))
        return SolidMaterial(modulus=float(np.exp(x[0])),
                             stiffening=float(np.exp(x[1])),
                             contact_radius=float(np.exp(x[2])), reach=float(np.exp(x[3])),
                             poisson=float(x[4]) if fit_poisson else start.poisson,
                             ratios=tuple(ratios))

    def fun(x: np.ndarray) -> np.ndarray:
        nonlocal evaluations
        evaluations += 1
        m = unpack(x)
        return np.concatenate([weighted(r).ravel() for r in
                               residuals(data, responses.at(data, m), m)])

    x0 = [np.log(start.modulus), np.log(start.stiffening),
          np.log(start.contact_radius), np.log(start.reach)] + \
        ([start.poisson] if fit_poisson else []) + \
        [np.log(start.ratios[k]) for k in fit_labels]
    # below the mesh's spacing the patch is one node whatever the radius: a flat objective
    radius = [np.log(max(CONTACT_RADIUS.min, PATCH_SPACINGS[0] * responses.model.spacing)),
              np.log(max(CONTACT_RADIUS.max, PATCH_SPACINGS[1] * responses.model.spacing))]
    reach = [np.log(REACH.min), np.log(REACH.max)]
    poisson = ([POISSON.min], [POISSON.max]) if fit_poisson else ([], [])
    stiff = np.log(STIFFENING_FIT)
    lo = [-np.inf, stiff[0], radius[0], reach[0]] + poisson[0] + \
        [np.log(RATIO_FIT[0])] * len(fit_labels)
    hi = [np.inf, stiff[1], radius[1], reach[1]] + poisson[1] + \
        [np.log(RATIO_FIT[1])] * len(fit_labels)
    x0 = np.clip(np.array(x0, dtype=np.float64), np.array(lo) + 1e-9, np.array(hi) - 1e-9)
    sol = least_squares(fun, x0, bounds=(lo, hi), diff_step=1e-3, x_scale="jac", xtol=1e-6,
                        ftol=1e-8)
    material = unpack(sol.x)
    per_press = residuals(data, responses.at(data, material), material)
    sd = _uncertainty(sol, per_press, names, material)
    return _scored(data, per_press, material, sd, evaluations, responses.factorisations)


def _uncertainty(sol: object, per_press: list[np.ndarray], names: list[str],
                 material: SolidMaterial) -> dict[str, float]:
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
    per_press = np.array([di[ok_i].mean() for di, ok_i in zip(dist, valid, strict=True)])
    return SolidFit(material=material, sd=sd, marker_mm=float(markers[ok_m].mean() * 1e3),
                    tip_mm=float(tips[ok_t].mean() * 1e3), all_mm=float(d[ok].mean() * 1e3),
                    still_mm=float(np.nanmean(np.where(ok_m, s, np.nan)) * 1e3),
                    per_marker_mm=per_marker * 1e3, per_press_mm=per_press * 1e3,
                    evaluations=evaluations,
                    factorisations=factorisations)

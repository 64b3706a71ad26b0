"""The solid's pre-training set: a plan of presses on the lab's markers, as a states file's
arrays (``phantom.states``, source ``solid``).

The plan is the MSM's (:mod:`sim.msm.msm_protocol`: places drawn among candidates, directions
within the cone, 15 steps to 7.5 N, multi-step pairs), drawn by the runner; its candidates
here are the top face's nodes inside the markers' bounding box, where the lab pressed. Each
place is three back-substitutions on one factorisation (:meth:`SolidModel.respond`), each
direction and level a weighted sum of them (:func:`sim.solid.solid_model.predict`). The points
are the lab's markers then the tip, as the lab's states are. On a curved block the directions
are drawn about each place's inward normal, as the twin's hand presses
(:func:`square_to_surface`, which the caller applies: it records what it applied).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from core.errors import BadInput
from sim.solid.elasticity import Solver
from sim.solid.solid_fit import SolidMaterial
from sim.solid.solid_model import Attachments, SolidModel, predict

CLEARANCE_SHARE = 0.25      # a place stays this share of the markers' spacing from each


@dataclass(frozen=True)
class SolidStates:
    """The states of a block of places, in file order (place, direction, level)."""

    points: np.ndarray      # (L * D * T, P + 1, 3) float32: the markers, then the tip
    tips: np.ndarray        # (L * D * T, 3) float32


def candidate_places(model: SolidModel, markers: np.ndarray, contact_radius: float
                     ) -> np.ndarray:
    """(C, 3) the top face's nodes inside the markers' bounding box (x, y), clear of every
    marker: further than the contact radius, or than a quarter of the markers' typical
    spacing where that is less. A lab presses beside its markers, never on one (the twin
    keeps two lattice spacings), and a marker under the tip's patch rides a load no lab
    applies."""
    rest, _ = model.top_face()
    lo, hi = markers[:, :2].min(axis=0), markers[:, :2].max(axis=0)
    inside = np.all((rest[:, :2] >= lo - 1e-9) & (rest[:, :2] <= hi + 1e-9), axis=1)
    between = np.linalg.norm(markers[:, None, :2] - markers[None, :, :2], axis=-1)
    np.fill_diagonal(between, np.inf)
    clearance = min(contact_radius, CLEARANCE_SHARE * float(np.median(between.min(axis=1))))
    gap = np.linalg.norm(rest[:, None, :2] - markers[None, :, :2], axis=-1).min(axis=1)
    found = rest[inside & (gap > clearance)]
    if not len(found):
        raise BadInput(None, f"no node of the solid's top face lies inside the markers' "
                             f"bounding box and {clearance * 1e3:.1f} mm clear of them: fit "
                             "the solid on a finer mesh (fit-solid --spacing-mm)")
    return found


def square_to_surface(model: SolidModel, places: np.ndarray, directions: np.ndarray
                      ) -> np.ndarray:
    """The directions (L, D, 3), drawn about -z, turned about each place's inward normal on a
    curved block (a hand presses square to the surface it sees); a flat block's as drawn."""
    shape = model.block.shape
    if shape is None:
        return directions
    normals = shape.closest(places)[1]
    down = np.array([0.0, 0.0, -1.0])
    return np.stack([Rotation.align_vectors(-n[None], down[None])[0].apply(d)
                     for n, d in zip(normals, directions, strict=True)])


def simulate_places(model: SolidModel, solver: Solver, material: SolidMaterial,
                    places: np.ndarray, directions: np.ndarray, forces: np.ndarray,
                    at: Attachments) -> SolidStates:
    """The states at ``places`` (L, 3) along ``directions`` (L, D, 3: as applied, turned to
    a curved surface by the caller, :func:`square_to_surface`) at ``forces`` (T,) N
    (ascending from 0)."""
    responses = model.respond(solver, places, material.contact_radius, model.probes(at))
    points, tips = [], []
    for resp, dirs in zip(responses, directions, strict=True):
        for d in dirs:
            loads = forces[:, None] * d[None]
            pts, tip = predict(resp, loads, material.modulus, material.stiffening,
                               material.reach, at)
            points.append(np.concatenate([pts, tip[:, None]], axis=1))
            tips.append(tip)
    return SolidStates(np.concatenate(points).astype(np.float32),
                       np.concatenate(tips).astype(np.float32))

"""The MSM seen where a lab sees its phantom: at marker positions, loaded over a contact patch.

Both the fit (:mod:`sim.msm.msm_fit`) and the lab-layout data set (:mod:`sim.msm.msm_dataset`)
compare or sample the MSM at points that are not its masses (25 markers at 20 mm pitch do not
sit on a 3.2 mm grid). A point at rest position (x, y) on the grid follows the bilinear blend of the
displacements of the four masses around it: no tie between two "nearest" masses, no jump
when a marker sits half-way. Everything is in the phantom frame, which is the grid's frame
(``[0, L] x [0, W]`` at z = 0, +z out of the surface).

An indenter is not a point: its tip touches the surface over a patch. ``contact_masses``
gives the masses within ``radius`` of the tip (at least the nearest one: the paper's n_n = 1);
``MSM.load`` shares the load equally among them (paper: F_t / n_n per mass), and the tip point
follows their mean displacement.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.msm.msm import MSM


@dataclass(frozen=True)
class Sampling:
    """Bilinear weights of the four masses around each point."""

    masses: np.ndarray       # (P, 4) mass indices
    weights: np.ndarray      # (P, 4), each row sums to 1

    def displace(self, disp: np.ndarray) -> np.ndarray:
        """The displacement (P, 3) of each point given the masses' displacements (N, 3)."""
        return np.einsum("pk,pkc->pc", self.weights, disp[self.masses])


def sample_at(model: MSM, xy: np.ndarray) -> Sampling:
    """Where points at rest positions ``xy`` (P, 2) m sit on the grid (clamped onto it).

    A non-finite position (a marker missing at rest) gets mass 0 with weight 0 (it follows
    nothing; its measured distance is left out).
    """
    p = model.params
    finite = np.isfinite(xy).all(axis=1)
    g = np.where(finite[:, None], xy, 0.0) / [p.spacing_x, p.spacing_y]
    g = np.clip(g, 0.0, np.array([model.cols, model.rows]) - 1 - 1e-9)
    base = np.floor(g).astype(np.int64)                     # (P, 2): column (x), row (y)
    t = g - base
    masses, weights = [], []
    for dy, dx in ((0, 0), (0, 1), (1, 0), (1, 1)):
        masses.append((base[:, 1] + dy) * model.cols + base[:, 0] + dx)
        wx = t[:, 0] if dx else 1 - t[:, 0]
        wy = t[:, 1] if dy else 1 - t[:, 1]
        weights.append(wx * wy * finite)
    return Sampling(np.stack(masses, 1), np.stack(weights, 1))


def contact_masses(model: MSM, tip_xy: np.ndarray, radius: float = 0.0) -> np.ndarray:
    """The masses within ``radius`` (m) of the tip's rest position, at least the nearest."""
    gap = np.linalg.norm(model.rest[:, :2] - tip_xy, axis=1)
    inside = np.flatnonzero(gap <= radius)
    return inside if len(inside) else np.array([int(gap.argmin())])

"""The twin phantom's spring forces on every node, summed spring by spring: a reference
independent of the solver's sparse matrices, for the equilibrium tests."""

from __future__ import annotations

import numpy as np

from sim.twin.phantom import Phantom


def nodal_forces(ph: Phantom, u: np.ndarray) -> np.ndarray:
    """Spring forces on every node (N, 3) for the free nodes' displacements ``u``: each spring's
    tension ``kappa * scale * L * (e + beta e^3)`` along its rest direction (``scale``: the
    spring's silicone over the block's, 1 in a uniform block)."""
    disp = np.zeros_like(ph.rest)
    free = ph.dof[:, 0] >= 0
    disp[free] = u.reshape(-1, 3)
    i, j = ph.springs[:, 0], ph.springs[:, 1]
    delta = ph.rest[j] - ph.rest[i]
    length = np.linalg.norm(delta, axis=1)
    n = delta / length[:, None]
    e = ((disp[j] - disp[i]) * n).sum(axis=1) / length
    tension = ph.kappa * ph.spring_scale * length * (e + ph.spec.stiffening * e**3)
    out = np.zeros_like(ph.rest)
    np.add.at(out, i, tension[:, None] * n)
    np.add.at(out, j, -tension[:, None] * n)
    return out

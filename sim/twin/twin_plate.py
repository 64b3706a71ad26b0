"""The force plate under the phantom (``--force-via plate``): what QTM's export of it holds.

The block stands on a force plate (a Kistler 9260AA6, 600 x 500 mm) lying on the table, its
axes the lab's and its origin the centre of its top surface, right under the phantom's bottom
centre. QTM zeroed the plate before the capture, so the block's weight is not in it. The plate
feels the indenter's push passed through the block: the force the indenter exerts on the
phantom (the twin's true contact force, lab frame, as the plate's frame), its moment about the
plate's origin (applied at the true tip) and the centre of pressure where its line of action
meets the top surface (:func:`core.force_plate.centre_of_pressure`). The samples are the
analog board's (:mod:`sim.twin.twin_force_log`): on the mocap's clock, a whole number per
frame. The values are the true wrench plus the plate's white noise (a few mN, drawn from the
seed's own stream for the plate): a noise-free force would leave the unloaded rest without a
noise width, and extract's contact start (where the force leaves it) without a meaning.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core.force_plate import centre_of_pressure
from sim.twin.twin import Twin
from sim.twin.twin_force_log import force_on_phantom


@dataclass(frozen=True)
class PlateSpec:
    """The plate as QTM's project names and places it."""

    name: str = "Force-plate 1"
    type: str = "Kistler"
    model: str = "9260AA6"
    length_mm: float = 600.0            # along the lab's x
    width_mm: float = 500.0             # along the lab's y
    noise_n: float = 0.005              # white noise sd of each force axis (N)
    noise_nm: float = 0.0005            # ... of each moment axis (N m)


PLATE = PlateSpec()
NOISE_STREAM = 8        # the seed's child stream for the plate's noise (simulate_twin uses 0-7)


def plate_origin(twin: Twin) -> np.ndarray:
    """The plate's origin (lab, m): the centre of its top surface, under the phantom's bottom
    centre."""
    return twin.to_lab[:3, 3].copy()


def plate_corners_mm(twin: Twin, plate: PlateSpec = PLATE) -> np.ndarray:
    """The plate's corners 1 to 4 (QTM's order: +x+y, -x+y, -x-y, +x-y) in the lab, mm."""
    half = np.array([plate.length_mm, plate.width_mm, 0.0]) / 2
    signs = np.array([[1, 1, 0], [-1, 1, 0], [-1, -1, 0], [1, -1, 0]])
    return plate_origin(twin) * 1e3 + signs * half


def plate_samples(twin: Twin, plate: PlateSpec = PLATE) -> np.ndarray:
    """The plate's samples (L, 9) at the force samples' times: force (N), moment about its
    origin (N m), centre of pressure (mm), each x, y, z in its frame."""
    t = twin.log.mocap_time_s
    force, moment = true_wrench(twin)
    rng = np.random.default_rng(np.random.SeedSequence(twin.params.seed).spawn(
        NOISE_STREAM + 1)[NOISE_STREAM])
    force = force + rng.normal(0.0, plate.noise_n, (len(t), 3))
    moment = moment + rng.normal(0.0, plate.noise_nm, (len(t), 3))
    return np.column_stack([force, moment, centre_of_pressure(force, moment) * 1e3])


def true_wrench(twin: Twin) -> tuple[np.ndarray, np.ndarray]:
    """The force (L, 3) on the plate at the force samples' times, and its moment about the
    plate's origin (applied at the true tip, interpolated between frames)."""
    t = twin.log.mocap_time_s
    force = force_on_phantom(twin.hand, twin.hand.state(t))
    true_tip = twin.mocap.points[:, -1]
    tip = np.column_stack([np.interp(t, twin.mocap.time_s, true_tip[:, k]) for k in range(3)])
    return force, np.cross(tip - plate_origin(twin), force)

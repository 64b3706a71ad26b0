"""The pivot-calibration recording of a synthetic session: the tip held in a divot on the
table while the cluster swings about it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.twin.indenter import IndenterGeometry, pivot_motion
from sim.twin.mocap_errors import gap_mask, residual_noise
from sim.twin.twin_scene import Lab, TwinParams


@dataclass
class Pivot:
    """The pivot-calibration recording (its own mocap clock)."""

    time_s: np.ndarray
    point: np.ndarray           # (3,) the divot
    rotation: np.ndarray        # (Q, 3, 3)
    cluster: np.ndarray         # (Q, 4, 3) truth
    measured: np.ndarray        # (Q, 4, 3) noisy, NaN in gaps


def play_pivot(p: TwinParams, indenter: IndenterGeometry, lab: Lab, g_pivot: np.random.Generator,
           g_gap: np.random.Generator) -> Pivot:
    """The tip in a divot on the table beside the phantom; the cluster swung about it."""
    time_s = np.arange(int(round(p.pivot_seconds * p.rate_hz))) / p.rate_hz
    point = lab(np.array([0.08, -0.02, 0.003]))
    rotation, cluster = pivot_motion(g_pivot, indenter, point, time_s)
    rates = np.full(cluster.shape[:2], p.errors.indenter_rate)
    measured = cluster + residual_noise(g_pivot, cluster.shape[:2], p.errors)
    measured[~gap_mask(g_gap, rates, p.rate_hz, p.errors)] = np.nan
    return Pivot(time_s=time_s, point=point, rotation=rotation, cluster=cluster,
                 measured=measured)

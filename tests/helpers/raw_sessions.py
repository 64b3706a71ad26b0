"""A small analytic session (RawSession) built in memory: presses alternating between two
places, a known clock offset and drift; shared by the sync tests and the bad-input tests."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from core.provenance import make_provenance
from core.series import ForceSeries, MarkerSeries, RawSession

RATE, LOG_RATE = 500.0, 1000.0
OFFSET, DRIFT = 0.8, 20.0                       # logger clock: OFFSET + (1 + DRIFT ppm) t_m
CLUSTER = np.array([[0, 0, 0.10], [0.045, 0, 0.10], [0, 0.03, 0.10], [0.012, 0.015, 0.138]])
PHANTOM = [f"P{i:02d}" for i in range(25)]
INDENTER = ["I1", "I2", "I3", "I4"]


def analytic_session(seed: int = 0, presses: int = 4, trigger: bool = True) -> RawSession:
    """Presses alternating between two places, tip in the body origin, force along z."""
    rng = np.random.default_rng(seed)
    t = np.arange(int((4 * presses + 3) * RATE)) / RATE
    gx, gy = np.meshgrid(np.linspace(-0.04, 0.04, 5), np.linspace(-0.04, 0.04, 5))
    phantom = np.stack([gx.ravel(), gy.ravel(), np.zeros(25)], axis=1)
    tip = np.zeros((len(t), 3))
    tip[:, 2] = 0.03
    for k in range(presses):
        s = (t - (1.5 + 4 * k)) / 2.0
        inside = (s >= 0) & (s <= 1)
        tip[inside, 2] = 0.03 - 0.036 * np.sin(np.pi * s[inside]) ** 2
        tip[(t >= 1 + 4 * k) & (t < 4.5 + 4 * k), 0] = 0.02 * (k % 2)
    rot = Rotation.from_euler("xy", [5, 3], degrees=True).as_matrix()
    pos = np.zeros((len(t), 29, 3))
    pos[:, :25] = phantom
    pos[:, 25:] = (CLUSTER @ rot.T)[None] + tip[:, None]
    pos += rng.normal(0, 0.1e-3, pos.shape)
    pulses = np.cumsum(rng.uniform(0.7, 1.3, int(t[-1])))
    pulses = pulses[pulses < t[-1]]
    t_ns = np.round(t * 1e9).astype(np.int64)
    markers = MarkerSeries("trial.tsv", t_ns, PHANTOM + INDENTER, pos, RATE,
                           events=[("Trigger", int(p * 1e9)) for p in pulses])
    tilt = np.column_stack([rng.uniform(-25, 25, 1500), rng.uniform(-25, 25, 1500),
                            np.zeros(1500)])
    rots = Rotation.from_euler("xyz", tilt, degrees=True).as_matrix()
    piv = np.einsum("kij,mj->kmi", rots, CLUSTER) + np.array([0.1, 0.1, 0.0])
    piv += rng.normal(0, 0.1e-3, piv.shape)
    pivot = MarkerSeries("pivot.tsv", np.arange(1500, dtype=np.int64) * 2_000_000, INDENTER,
                         piv, RATE)
    t_f = np.arange(0, t[-1] + 1.0, 1 / LOG_RATE)
    depth = np.interp((t_f - OFFSET) / (1 + DRIFT * 1e-6), t, -tip[:, 2], left=-1, right=-1)
    wrench = np.zeros((len(t_f), 6))
    wrench[:, 2] = 7.0 * (np.clip(depth, 0, None) / 0.006) ** 1.5
    wrench += rng.normal(0, 0.005, wrench.shape) + np.array([0.1, -0.2, 0.3, 0.01, 0, 0])
    ttl = np.zeros(len(t_f))
    for p in pulses:
        at = OFFSET + (1 + DRIFT * 1e-6) * p
        ttl[(t_f >= at) & (t_f < at + 0.01)] = 5.0
    force = ForceSeries("force.csv", np.round(t_f * 1e9).astype(np.int64),
                        ["Fx", "Fy", "Fz", "Tx", "Ty", "Tz"], wrench,
                        ["N"] * 3 + ["N*m"] * 3, "wrench", LOG_RATE,
                        trigger=ttl if trigger else None)
    return RawSession("analytic", markers, force, PHANTOM, INDENTER, pivot=pivot,
                      trigger_event="Trigger" if trigger else None,
                      provenance=make_provenance("test", {"seed": seed}, [],
                                                 "phantom.raw_mcap", "1.0"))

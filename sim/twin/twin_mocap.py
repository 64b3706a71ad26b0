"""The trial as Qualisys saw it: the truth on the mocap clock and what the cameras delivered.

Phantom markers and tip follow the solved phantom along each press; the indenter cluster rides
the hand's pose. Noise and occlusion gaps (:mod:`sim.twin.mocap_errors`) give the measured markers,
and QTM's 6D body is the body fitted to the measured cluster, as QTM computes it
(:mod:`sim.twin.body_fit`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.twin.body_fit import qtm_body
from sim.twin.indenter import Hand, IndenterGeometry
from sim.twin.mocap_errors import gap_mask, gap_rates, residual_noise
from sim.twin.phantom import LoadPath, Phantom
from sim.twin.twin_force_log import contact_wrench
from sim.twin.twin_scene import Lab, TwinParams


@dataclass
class Mocap:
    """The trial on the mocap clock: truth and what the cameras delivered."""

    time_s: np.ndarray          # (T,)
    points: np.ndarray          # (T, N + 1, 3) truth: the N phantom markers + tip
    cluster: np.ndarray         # (T, 4, 3) truth
    origin: np.ndarray          # (T, 3) body origin
    rotation: np.ndarray        # (T, 3, 3) body -> lab
    press: np.ndarray           # (T,) press in contact or -1
    force: np.ndarray           # (T,) contact force magnitude
    force_lab: np.ndarray       # (T, 3) on the phantom
    force_sensor: np.ndarray    # (T, 3) on the tip, sensor frame
    torque_sensor: np.ndarray   # (T, 3)
    visible: np.ndarray         # (T, N + 4): phantom markers, then the indenter's
    measured: np.ndarray        # (T, N + 4, 3) noisy, NaN in gaps
    body_origin: np.ndarray     # (T, 3) QTM's 6D fit of the measured cluster, NaN when lost
    body_rotation: np.ndarray   # (T, 3, 3)
    body_residual: np.ndarray   # (T,)
    events: list[tuple[str, int, float]]


def play_mocap(p: TwinParams, phantom: Phantom, lab: Lab, hand: Hand, paths: list[LoadPath],
           indenter: IndenterGeometry, time_s: np.ndarray, g_cam: np.random.Generator,
           g_gap: np.random.Generator) -> Mocap:
    """Every mocap frame of the trial: the truth, then the noisy, gappy measurement."""
    st = hand.state(time_s)
    rest_markers = lab(phantom.observe(np.zeros(phantom.n_dof))[1])
    tip = st.tip_air.copy()
    markers = np.repeat(rest_markers[None], len(time_s), axis=0)
    force_lab = np.zeros((len(time_s), 3))
    for k, path in enumerate(paths):
        idx = np.flatnonzero(st.press == k)
        tip[idx] = lab(path.interpolate(st.force[idx], "tip"))
        markers[idx] = lab(path.interpolate(st.force[idx], "markers"))
        force_lab[idx] = st.force[idx, None] * hand.presses[k].direction
    cluster = tip[:, None] + np.einsum("tij,mj->tmi", st.rotation,
                                       indenter.markers - indenter.tip)
    origin = tip - st.rotation @ indenter.tip
    force_sensor, torque = contact_wrench(indenter, st.rotation, force_lab)

    truth = np.concatenate([markers, cluster], axis=1)
    top = lab(np.array([0.0, 0.0, p.phantom.size[2]]))[2]
    rates = gap_rates(tip, tip[:, 2] - top, rest_markers, cluster.shape[1], p.errors)
    visible = gap_mask(g_gap, rates, p.rate_hz, p.errors)
    measured = truth + residual_noise(g_cam, truth.shape[:2], p.errors)
    measured[~visible] = np.nan
    body_origin, body_rotation, body_residual = qtm_body(indenter.markers,
                                                         measured[:, phantom.n_markers:])
    return Mocap(
        time_s=time_s, points=np.concatenate([markers, tip[:, None]], axis=1), cluster=cluster,
        origin=origin, rotation=st.rotation, press=st.press, force=st.force,
        force_lab=force_lab, force_sensor=force_sensor, torque_sensor=torque,
        visible=visible, measured=measured, body_origin=body_origin,
        body_rotation=body_rotation, body_residual=body_residual, events=[])

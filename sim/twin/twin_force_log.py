"""The Speedgoat force log of a synthetic session: a Nano17 on the logger's own clock.

The logger's clock runs ``t_f = offset_s + (1 + drift_ppm * 1e-6) * t_m`` against the mocap's;
the log starts before the mocap, with the indenter still and unloaded (so it can be tared), and
ends after it. The sensor feels the contact wrench and the tool's weight; TTL pulses at
irregular intervals go to the trigger channel.

With ``force_via = "analog"`` the Nano17's amplifier is wired into the mocap system's analog
board instead: the samples are on the mocap's clock (offset 0, drift 0), a whole number per
frame, from the first frame to the last frame's end, as QTM records them. A force plate under
the phantom (``force_via = "plate"``, :mod:`sim.twin.twin_plate`) is sampled at the same
times.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.twin.indenter import GRAVITY, Hand, HandState, IndenterGeometry
from sim.twin.nano17 import Nano17
from sim.twin.twin_scene import TwinParams


@dataclass
class ForceLog:
    """The Speedgoat log on its own clock, with the truth behind it."""

    time_s: np.ndarray          # (L,) logger clock
    mocap_time_s: np.ndarray    # (L,)
    force: np.ndarray           # (L, 3) contact force on the tip, sensor frame
    torque: np.ndarray          # (L, 3)
    tool_force: np.ndarray      # (L, 3)
    volts: np.ndarray           # (L, 6)
    trigger: np.ndarray | None  # (L,) volts
    offset_s: float
    drift_ppm: float
    pulses: np.ndarray          # (K,) rising edges, mocap clock


def play_force_log(p: TwinParams, hand: Hand, indenter: IndenterGeometry, sensor: Nano17,
               last_frame_s: float, g_force: np.random.Generator,
               g_clock: np.random.Generator) -> ForceLog:
    """Logger samples on its own clock, covering the mocap with an unloaded lead.

    The clock's offset and drift are always drawn, then replaced by ``p.offset_s`` and
    ``p.drift_ppm`` where given: setting them changes no other random choice.
    """
    sign = g_clock.choice([-1.0, 1.0], 2)
    offset = sign[0] * g_clock.uniform(0.3, 3.0)
    drift = sign[1] * g_clock.uniform(10.0, 60.0)
    offset = offset if p.offset_s is None else p.offset_s
    drift = drift if p.drift_ppm is None else p.drift_ppm
    lead, tail = g_clock.uniform(1.5, 3.0), g_clock.uniform(0.5, 2.0)
    if p.on_mocap_clock:
        offset, drift = 0.0, 0.0
        per_frame = int(round(p.logger_hz / p.rate_hz))
        t_f = np.arange((int(round(last_frame_s * p.rate_hz)) + 1) * per_frame) / p.logger_hz
    else:
        scale = 1.0 + drift * 1e-6
        first = int(np.ceil((offset - scale * lead) * p.logger_hz))
        last = int(np.floor((offset + scale * (last_frame_s + tail)) * p.logger_hz))
        t_f = np.arange(first, last + 1) / p.logger_hz
    scale = 1.0 + drift * 1e-6
    t_m = (t_f - offset) / scale

    st = hand.state(t_m)
    force, torque = contact_wrench(indenter, st.rotation, force_on_phantom(hand, st))
    tool = np.einsum("tji,j->ti", st.rotation, indenter.tool_mass * GRAVITY)
    tool_torque = np.cross(indenter.tool_centre - indenter.sensor, tool)
    volts = sensor.volts(g_force, force + tool, torque + tool_torque, t_f)

    pulses = np.array([])
    trigger = None
    if p.trigger:
        pulses = pulse_times(g_clock, last_frame_s)
        k = np.searchsorted(pulses, t_m, side="right") - 1
        high = (k >= 0) & (t_m < pulses[np.maximum(k, 0)] + 0.010)
        trigger = np.where(high, 5.0, 0.0) + g_force.normal(0.0, 0.002, len(t_m))
    return ForceLog(time_s=t_f, mocap_time_s=t_m, force=force, torque=torque, tool_force=tool,
                    volts=volts, trigger=trigger, offset_s=float(offset),
                    drift_ppm=float(drift), pulses=pulses)


def force_on_phantom(hand: Hand, st: HandState) -> np.ndarray:
    """The force (T, 3) the indenter exerts on the phantom at the hand's states, lab frame
    (0 in the air)."""
    directions = np.vstack([np.zeros(3), *(q.direction for q in hand.presses)])
    return st.force[:, None] * directions[st.press + 1]


def contact_wrench(indenter: IndenterGeometry, rotation: np.ndarray, force_lab: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Force and torque (T, 3) the sensor feels from the contact, in its own frame.

    ``force_lab`` (T, 3) is the force the indenter exerts on the phantom; the phantom pushes
    back on the tip with its opposite, applied at the tip, taken about the sensor's origin.
    ``rotation`` (T, 3, 3) is body (= sensor axes) to lab.
    """
    force = -np.einsum("tji,tj->ti", rotation, force_lab)
    return force, np.cross(indenter.tip - indenter.sensor, force)


def pulse_times(rng: np.random.Generator, end_s: float) -> np.ndarray:
    """TTL sync pulses at irregular intervals (so that no shift of the train fits but one)."""
    times, t = [], rng.uniform(0.3, 0.8)
    while t < end_s - 0.3:
        times.append(t)
        t += rng.uniform(0.7, 2.3)
    return np.array(times)

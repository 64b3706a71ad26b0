"""The phantom twin: a whole lab session simulated in memory (:func:`simulate_twin`).

A volumetric silicone block (:mod:`sim.twin.phantom`) on the table, markers on its top (5 x 5
20 mm apart by default; any grid, a scattered layout, any footprint:
:mod:`sim.twin.marker_layout`), an indenter cluster held by a hand (:mod:`sim.twin.indenter`)
pressing each location several times (:mod:`sim.twin.twin_scene`), seen by Qualisys with
noise and occlusions (:mod:`sim.twin.twin_mocap`, QTM's 6D body: :mod:`sim.twin.body_fit`),
a Nano17 logged by a Speedgoat on its own clock (:mod:`sim.twin.twin_force_log`), a pivot
calibration (:mod:`sim.twin.twin_pivot`) and the true static states
(:mod:`sim.twin.twin_states`). :mod:`sim.twin.synth_stage` writes it as the lab would, with
``truth.h5`` (:mod:`sim.twin.twin_truth`). The same seed gives the same session.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from sim.twin.indenter import (
    Hand,
    HandStyle,
    IndenterGeometry,
    make_indenter,
    plan_hand,
    tilt_to_normals,
)
from sim.twin.nano17 import Nano17, make_nano17
from sim.twin.phantom import LoadPath, Phantom
from sim.twin.twin_force_log import ForceLog, play_force_log
from sim.twin.twin_mocap import Mocap, play_mocap
from sim.twin.twin_pivot import Pivot, play_pivot
from sim.twin.twin_scene import (
    TRIGGER_EVENT,
    TwinParams,
    check_params,
    choose_locations,
    grid_locations,
    placement,
    solve_presses,
    to_lab_frame,
)
from sim.twin.twin_states import TrueStates, true_states

ANALOG_LEAD_IN_S = 3.0     # s the hand holds still before its first move (force on the
                           # mocap's clock: its analog board, its force plate)


@dataclass
class Twin:
    """A simulated session in memory, ready to be written."""

    params: TwinParams
    phantom: Phantom
    to_lab: np.ndarray          # (4, 4)
    nodes: np.ndarray           # (C, 2) top lattice nodes of the locations
    contacts: np.ndarray        # (C, 3) lab
    indenter: IndenterGeometry
    sensor: Nano17
    hand: Hand
    paths: list[LoadPath]
    mocap: Mocap
    log: ForceLog
    pivot: Pivot
    states: TrueStates

    def lab(self, p: np.ndarray) -> np.ndarray:
        """Phantom-frame points (..., 3) in the lab."""
        return to_lab_frame(self.to_lab, p)



def _lead_in(p: TwinParams) -> float:
    """Seconds the hand holds the indenter still before its first move. The Speedgoat log
    starts seconds before the capture; sampled by the mocap system (its analog board, its
    force plate) the force starts with the capture, so the hand waits longer there: sync
    tares from the first 2 s when they are quiet.
    """
    return ANALOG_LEAD_IN_S if p.on_mocap_clock else 1.0


def simulate_twin(p: TwinParams) -> Twin:
    """Play the whole session in memory."""
    check_params(p)
    rng = [np.random.default_rng(s) for s in np.random.SeedSequence(p.seed).spawn(8)]
    g_place, g_hand, g_cam, g_force, g_clock, g_pivot, g_build, g_gap = rng
    phantom = Phantom(p.phantom)
    to_lab = placement(g_place)
    lab = partial(to_lab_frame, to_lab)
    nodes = (choose_locations(g_place, phantom, p.locations) if isinstance(p.locations, int)
             else grid_locations(phantom, *p.locations))
    contacts = lab(np.array([phantom.contact_point(tuple(ij)) for ij in nodes]))
    targets = [(loc, rep, contacts[loc]) for rep in range(p.repeats)
               for loc in range(p.places)]
    style = HandStyle()
    if p.press_seconds is not None:
        style = replace(style, scale=p.press_seconds / style.mean_press_s)
    hand = plan_hand(g_hand, targets, style, lead_in=_lead_in(p))
    if phantom.spec.shape is not None:
        tilt_to_normals(hand, [to_lab[:3, :3] @ phantom.rest_normal(tuple(ij)) for ij in nodes])
    paths = solve_presses(phantom, hand, nodes, to_lab)
    indenter = make_indenter(g_build)
    sensor = make_nano17(g_build, f"FT{21000 + p.seed % 79000:05d}")
    frames = int(np.ceil(hand.end * p.rate_hz))
    time_s = np.arange(frames) / p.rate_hz
    mocap = play_mocap(p, phantom, lab, hand, paths, indenter, time_s, g_cam, g_gap)
    log = play_force_log(p, hand, indenter, sensor, time_s[-1], g_force, g_clock)
    mocap.events = [(TRIGGER_EVENT, int(np.floor(t * p.rate_hz + 1e-9)) + 1, float(t))
                    for t in log.pulses] if p.trigger else []
    pivot = play_pivot(p, indenter, lab, g_pivot, g_gap)
    states = true_states(hand, paths, lab, mocap)
    return Twin(params=p, phantom=phantom, to_lab=to_lab, nodes=nodes, contacts=contacts,
                indenter=indenter, sensor=sensor, hand=hand, paths=paths, mocap=mocap, log=log,
                pivot=pivot, states=states)

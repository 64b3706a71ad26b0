"""Where the twin presses: N places drawn at random (as before) or an R x C grid over the
nodes a press may target, checked against the lattice's geometry."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import BadInput
from sim.twin.phantom import Phantom, PhantomSpec
from sim.twin.synth_params import SynthParams
from sim.twin.twin_scene import TwinParams, check_params, grid_locations, parse_locations


@pytest.fixture(scope="module")
def phantom() -> Phantom:
    return Phantom()


def footprint_mm(ph: Phantom, nodes: np.ndarray) -> np.ndarray:
    """(P, 2) the nodes' places on the footprint [0, L] x [0, W], mm."""
    xy = np.array([ph.contact_point(tuple(n))[:2] for n in nodes])
    return np.round((xy + np.array(ph.spec.size[:2]) / 2) * 1e3, 6)


def test_a_4x4_grid_is_every_cell_between_four_markers(phantom: Phantom) -> None:
    """The default 5 x 5 markers 20 mm apart (at 10, 30, .. 90 mm) and presses 20 mm inside
    the edges: the 4x4 grid is the 16 cell centres between four markers, row-major (rows along
    +x at increasing y), each a place a press may target."""
    nodes = grid_locations(phantom, 4, 4)
    want = [(x, y) for y in (20, 40, 60, 80) for x in (20, 40, 60, 80)]
    np.testing.assert_array_equal(footprint_mm(phantom, nodes), want)
    assert {tuple(n) for n in nodes} <= {tuple(c) for c in phantom.candidate_locations()}


def test_smaller_grids_span_the_same_area(phantom: Phantom) -> None:
    """2 x 3 and 3 x 3: the extent's edges and its middle (50 mm); where the middle is a
    marker, the nearest node a press may target, 10 mm off (a tie: the smaller x). One place
    alone: that node."""
    np.testing.assert_array_equal(footprint_mm(phantom, grid_locations(phantom, 2, 3)),
                                  [(20, 20), (50, 20), (80, 20), (20, 80), (50, 80), (80, 80)])
    np.testing.assert_array_equal(footprint_mm(phantom, grid_locations(phantom, 3, 3)),
                                  [(20, 20), (50, 20), (80, 20), (20, 50), (40, 50), (80, 50),
                                   (20, 80), (50, 80), (80, 80)])
    np.testing.assert_array_equal(footprint_mm(phantom, grid_locations(phantom, 1, 1)),
                                  [(40, 50)])


def test_a_larger_block_takes_a_5x5_grid() -> None:
    """The 5 x 5 markers on a 150 x 150 mm block: presses may reach 20..130 mm; 25 places
    row-major, each a target node within 10 mm of its evenly spread point, 15 mm apart."""
    ph = Phantom(PhantomSpec(size=(0.15, 0.15, 0.032)))
    nodes = grid_locations(ph, 5, 5)
    at = footprint_mm(ph, nodes)
    cand = footprint_mm(ph, ph.candidate_locations())
    lo, hi = cand.min(axis=0), cand.max(axis=0)
    target = np.array([(x, y) for y in np.linspace(lo[1], hi[1], 5)
                       for x in np.linspace(lo[0], hi[0], 5)])
    assert np.linalg.norm(at - target, axis=1).max() <= 10.0
    assert {tuple(n) for n in nodes} <= {tuple(c) for c in ph.candidate_locations()}
    gap = np.linalg.norm(at[:, None] - at[None], axis=2) + 1e9 * np.eye(25)
    assert gap.min() >= 15.0


def test_a_grid_the_layout_cannot_hold_is_refused(phantom: Phantom) -> None:
    with pytest.raises(BadInput, match="5x5 grid of places does not fit") as err:
        grid_locations(phantom, 5, 5)
    assert str(err.value).startswith("--locations") and "\n" not in str(err.value)


@pytest.mark.parametrize("text, want", [("5", 5), ("3x3", (3, 3)), (" 2 X 4 ", (2, 4)),
                                        (7, 7), ("5x5", (5, 5))])
def test_locations_read_as_a_number_or_a_grid(text, want) -> None:
    assert parse_locations(text) == want


@pytest.mark.parametrize("text", ["0", "0x3", "6x5", "3x", "three", "-2"])
def test_bad_locations_are_refused(text) -> None:
    with pytest.raises(BadInput, match="--locations"):
        parse_locations(text)
    with pytest.raises(BadInput, match="--locations"):
        SynthParams(locations=text)


def test_the_grid_is_checked_for_a_library_caller_too() -> None:
    with pytest.raises(BadInput, match="--locations"):
        check_params(TwinParams(locations=(6, 6)))
    assert TwinParams(locations=(3, 4)).places == 12 and TwinParams().places == 5
    assert SynthParams(locations="3x4").places == 12

"""Inclusions and a top layer in the twin's block: the series rule on single springs against
its closed form, the block they make against the uniform block, and the refusals."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.phantom_springs import nodal_forces

from core.errors import BadInput
from sim.twin.material_regions import (
    Inclusion,
    Layer,
    parse_inclusion,
    parse_layer,
    series_scale,
    spring_scale,
)
from sim.twin.phantom import Phantom, PhantomSpec
from sim.twin.synth_params import SynthParams

SIZE = (0.100, 0.100, 0.032)            # the default block (m)
BAND = 0.008                            # its node layers' spacing
TOP = SIZE[2]
DOWN = np.array([0.0, 0.0, -1.0])
CENTRE = (10, 10)                       # the top node at the footprint's centre (50, 50) mm
AWAY = (16, 16)                         # (80, 80) mm
LUMP = Inclusion(0.050, 0.050, 0.010, 0.012, 3.0)   # the issue's: 3x, r 12 mm, 10 mm deep


def segment(a: tuple[float, float, float], b: tuple[float, float, float]
            ) -> tuple[np.ndarray, np.ndarray]:
    return np.array([a]), np.array([b])


def test_a_vertical_spring_through_a_layer_is_springs_in_series() -> None:
    """8 mm down from the surface through a 3 mm layer 3x as stiff: 3/8 of it at 3k, 5/8 at
    k; in series 1 / (3/8 / 3 + 5/8) = 4/3."""
    p0, p1 = segment((0.0, 0.0, TOP), (0.0, 0.0, TOP - 0.008))
    got = spring_scale(p0, p1, (), Layer(0.003, 3.0), SIZE, BAND)
    assert got[0] == pytest.approx(4.0 / 3.0, rel=1e-12)
    softer = spring_scale(p0, p1, (), Layer(0.003, 0.5), SIZE, BAND)
    assert softer[0] == pytest.approx(1.0 / (0.375 / 0.5 + 0.625), rel=1e-12)


def test_a_spring_through_a_sphere_scales_by_its_chord() -> None:
    """A body diagonal passing 3 mm from the centre of a 5 mm sphere: the chord is
    2 sqrt(25 - 9) = 8 mm of its length; and one that misses it is the block's."""
    c = LUMP.centre(SIZE)
    d = np.array([5.0, 5.0, 8.0]) * 1e-3
    d /= np.linalg.norm(d)
    off = np.cross(d, [1.0, 0.0, 0.0])
    off = 0.003 * off / np.linalg.norm(off)
    half = 0.0085
    p0, p1 = (c + off - half * d)[None], (c + off + half * d)[None]
    inc = Inclusion(LUMP.x, LUMP.y, LUMP.depth, 0.005, 4.0)
    share = 0.008 / (2 * half)
    want = 1.0 / (share / 4.0 + 1.0 - share)
    assert series_scale(p0, p1, (inc,), None, SIZE)[0] == pytest.approx(want, rel=1e-9)
    miss = series_scale(p0 + 3 * off, p1 + 3 * off, (inc,), None, SIZE)
    assert miss[0] == 1.0


def test_a_horizontal_spring_stands_for_its_band_in_parallel() -> None:
    """A surface spring stands for the top 4 mm (half a node layer): under a 3 mm layer of 3x
    silicone, 3/4 of that band is 3k and 1/4 k, side by side: 2.5 k. A spring in the node layer
    8 mm down, with a layer 8 mm thick: half its band either side, (3 + 1) / 2 = 2."""
    p0, p1 = segment((0.0, 0.0, TOP), (0.005, 0.0, TOP))
    assert spring_scale(p0, p1, (), Layer(0.003, 3.0), SIZE, BAND)[0] == pytest.approx(2.5)
    q0, q1 = segment((0.0, 0.0, TOP - 0.008), (0.005, 0.005, TOP - 0.008))
    assert spring_scale(q0, q1, (), Layer(0.008, 3.0), SIZE, BAND)[0] == pytest.approx(2.0)
    thin = spring_scale(p0, p1, (), Layer(0.0005, 3.0), SIZE, BAND)[0]
    assert 1.0 < thin < 1.3                  # a thin skin fades towards none, not all


def test_an_inclusion_in_the_layer_keeps_its_own_silicone() -> None:
    """A vertical spring from the surface down 8 mm, through a 3 mm layer (2x) and a sphere
    whose top is 1 mm down (5x, r 4 mm, centre 5 mm deep): 0-1 mm layer, 1-8 mm sphere."""
    inc = Inclusion(0.050, 0.050, 0.005, 0.004, 5.0)
    c = inc.centre(SIZE)
    p0, p1 = segment((c[0], c[1], TOP), (c[0], c[1], TOP - 0.008))
    want = 1.0 / (1 / 8 / 2.0 + 7 / 8 / 5.0)
    assert series_scale(p0, p1, (inc,), Layer(0.003, 2.0), SIZE)[0] == pytest.approx(want)


@pytest.fixture(scope="module")
def uniform() -> Phantom:
    return Phantom()


def depth_mm(ph: Phantom, ij: tuple[int, int], force: float) -> float:
    tip = ph.load_path(ij, DOWN, np.array([force])).tip[:, 2]
    return float(tip[0] - tip[1]) * 1e3


def test_a_layer_of_ratio_one_is_the_uniform_block_exactly(uniform: Phantom) -> None:
    same = Phantom(PhantomSpec(layer=Layer(0.003, 1.0), inclusions=(
        Inclusion(0.030, 0.070, 0.012, 0.010, 1.0),)))
    assert np.array_equal(same.spring_scale, np.ones(len(same.springs)))
    a = uniform.load_path(CENTRE, DOWN, np.array([1.0, 4.0]))
    b = same.load_path(CENTRE, DOWN, np.array([1.0, 4.0]))
    assert np.array_equal(a.surface, b.surface) and np.array_equal(a.tip, b.tip)


def test_a_lump_under_the_press_sinks_it_less(uniform: Phantom) -> None:
    """The issue's lump (3x, r 12 mm, 10 mm deep) under a 2 N press: far shallower than the
    uniform block; the same press 42 mm away from it barely notices; a 0.3x lump sinks deeper."""
    plain = depth_mm(uniform, CENTRE, 2.0)
    lump = Phantom(PhantomSpec(inclusions=(LUMP,)))
    over = depth_mm(lump, CENTRE, 2.0)
    away = depth_mm(lump, AWAY, 2.0)
    assert over < 0.75 * plain
    assert away == pytest.approx(depth_mm(uniform, AWAY, 2.0), rel=0.01)
    soft = Phantom(PhantomSpec(inclusions=(Inclusion(0.05, 0.05, 0.010, 0.012, 0.3),)))
    assert depth_mm(soft, CENTRE, 2.0) > 1.3 * plain


def test_a_stiffer_skin_sinks_the_press_less_and_a_thicker_one_still_less(uniform) -> None:
    plain = depth_mm(uniform, CENTRE, 2.0)
    thin = depth_mm(Phantom(PhantomSpec(layer=Layer(0.003, 3.0))), CENTRE, 2.0)
    thick = depth_mm(Phantom(PhantomSpec(layer=Layer(0.016, 3.0))), CENTRE, 2.0)
    assert thick < thin < plain


def test_equilibrium_holds_with_the_scaled_springs() -> None:
    """Spring by spring (the solver's sparse matrices unused): each free node balanced, the
    table carrying the load, with every spring's stiffness ``kappa * scale``."""
    ph = Phantom(PhantomSpec(inclusions=(LUMP,), layer=Layer(0.003, 0.5)))
    assert ph.spring_scale.min() < 1.0 < ph.spring_scale.max()
    load = np.zeros(ph.n_dof)
    node = ph.top(*CENTRE)
    load[ph.dof[node]] = 3.0 * DOWN
    forces = nodal_forces(ph, ph.solve(load))
    free = ph.dof[:, 0] >= 0
    applied = np.zeros_like(ph.rest)
    applied[node] = 3.0 * DOWN
    assert np.abs(forces[free] + applied[free]).max() < 2 * ph.spec.tol
    np.testing.assert_allclose(forces[~free].sum(axis=0), 3.0 * DOWN, atol=1e-3)


def test_a_press_that_would_sink_through_the_table_is_refused() -> None:
    """A soft 0.3x lump under an 8 N press: the linearised lattice would put the surface below
    the table; one line, naming the press and the soft silicone."""
    soft = Phantom(PhantomSpec(inclusions=(Inclusion(0.05, 0.05, 0.010, 0.012, 0.3),)))
    with pytest.raises(BadInput, match=r"below the table.*0\.3x") as err:
        soft.load_path(CENTRE, DOWN, np.array([4.0, 8.0]))
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("make, match", [
    (lambda: parse_inclusion("150,50,10,12,3"), "centre is outside"),
    (lambda: PhantomSpec(inclusions=(Inclusion(0.05, 0.05, 0.040, 0.012, 3.0),)),
     "centre is outside"),
    (lambda: parse_inclusion("50,50,10,12,-3"), "ratio -3: must be in"),
    (lambda: parse_inclusion("50,50,10,12,11"), "ratio 11: must be in"),
    (lambda: parse_inclusion("50,50,10,0.5,3"), "radius 0.5 mm"),
    (lambda: parse_inclusion("50,50,10,12"), "X,Y,DEPTH,RADIUS,RATIO"),
    (lambda: parse_inclusion("50,50,nan,12,3"), "not a finite number"),
    (lambda: parse_layer("40,2"), "thinner than"),
    (lambda: parse_layer("32,2"), "thinner than"),
    (lambda: parse_layer("3,0.1"), "ratio 0.1"),
    (lambda: parse_layer("-3,2"), "must be > 0"),
    (lambda: SynthParams(inclusions=("50,50,10,12,3", "60,55,12,10,2")), "overlap"),
    (lambda: SynthParams(size="60x60", inclusions=("80,30,10,12,3",)), "centre is outside"),
    (lambda: SynthParams(layer="32,2"), "thinner than"),
])
def test_regions_a_block_cannot_hold_are_refused_in_one_line(make, match) -> None:
    """The same refusal for a library caller (the dataclasses, the settings) as for the
    command line, whose option types call the same parsers."""
    with pytest.raises(BadInput, match=match) as err:
        spec = make()
        if isinstance(spec, (Inclusion, Layer)):      # the block's check: as PhantomSpec makes it
            PhantomSpec(inclusions=(spec,) if isinstance(spec, Inclusion) else (),
                        layer=spec if isinstance(spec, Layer) else None)
    assert "\n" not in str(err.value)
    assert str(err.value).startswith(("--inclusion", "--layer"))

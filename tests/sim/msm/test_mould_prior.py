"""Curved phantoms drawn from the prior over moulds: caps of the stated geometry, every draw in
its ranges and drawn from its seed and block alone, the modulus that sends the centre press as
deep as drawn, and a states file a trainer reads (``simulate --prior --moulds``)."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from core.recording import rrd_entities
from data_schema.states import validate_states
from pipeline.cli import cli
from sim.msm.mould_prior import MOULDS, Cap, cap_span, cap_top, draw_mould, modulus_for_depth
from sim.msm.mould_prior_data import centre_modulus
from sim.msm.msm_prior import PRIOR
from sim.solid.elasticity import Solver
from sim.solid.fit_solid_params import FitSolidParams
from sim.solid.solid_model import predict, stiffened
from train.training.variant import source_name

BLOCKS = range(6)


@pytest.fixture(scope="module")
def phantoms():
    return [draw_mould(MOULDS, 3, b, 2, 2) for b in BLOCKS]


def test_a_dome_is_the_sphere_through_the_footprints_corners() -> None:
    """Height 0 at the four corners, ``height`` at the centre, and every point of the cap on
    one sphere (its centre on the vertical through the footprint's)."""
    size, h = (0.12, 0.08), 0.03
    top = cap_top(Cap.DOME, size, h)
    corners = np.array([[0, 0], [0.12, 0], [0, 0.08], [0.12, 0.08]])
    np.testing.assert_allclose(top(corners), 0.0, atol=1e-12)
    np.testing.assert_allclose(top(np.array([[0.06, 0.04]])), h, rtol=1e-12)
    xy = np.random.default_rng(0).uniform([0, 0], size, (50, 2))
    r = (0.06 ** 2 + 0.04 ** 2 + h ** 2) / (2 * h)                 # the sphere's radius
    dist = np.linalg.norm(np.c_[xy - [0.06, 0.04], top(xy) - (h - r)], axis=1)
    np.testing.assert_allclose(dist, r, rtol=1e-12)


def test_a_cap_is_never_higher_than_its_half_span(phantoms) -> None:
    """Higher than a half-cylinder the surface through the edges would rise as walls: refused
    to the geometry, and never drawn."""
    with pytest.raises(ValueError):
        cap_top(Cap.RIDGE_X, (0.10, 0.06), 0.031)
    cap_top(Cap.RIDGE_X, (0.10, 0.06), 0.030)           # a half-cylinder: the edges at 0
    for ph in phantoms:
        assert ph.height <= cap_span(ph.cap, ph.model.block.footprint)[0]


def test_a_ridge_is_a_cylinder_along_its_axis() -> None:
    """Along x: the same height along x, 0 on the two long edges, ``height`` midway."""
    size, h = (0.10, 0.06), 0.02
    top = cap_top(Cap.RIDGE_X, size, h)
    y = np.array([0.0, 0.03, 0.06])
    for x in (0.0, 0.037, 0.1):
        np.testing.assert_allclose(top(np.c_[np.full(3, x), y]), [0.0, h, 0.0], atol=1e-12)
    across = cap_top(Cap.RIDGE_Y, size, h)
    np.testing.assert_allclose(across(np.array([[0.0, 0.01], [0.05, 0.01], [0.1, 0.01]])),
                               [0.0, h, 0.0], atol=1e-12)


def test_every_draw_lies_in_its_ranges(phantoms) -> None:
    """Cap, block, material, markers (on the cap by a marker's radius) and places (on the top
    face, clear of the markers)."""
    m = MOULDS
    for ph in phantoms:
        size = np.array(ph.model.block.footprint)
        assert m.height[0] <= ph.height <= m.height[1]
        assert m.thickness[0] <= ph.thickness <= m.thickness[1]
        assert ((m.side[0] <= size) & (size <= m.side[1])).all()
        assert m.stiffening[0] <= ph.stiffening <= m.stiffening[1]
        assert m.reach[0] <= ph.reach <= m.reach[1]
        assert m.contact_radius[0] <= ph.plan.protocol.contact_radius <= m.contact_radius[1]
        assert PRIOR.markers[0] <= len(ph.layout) <= PRIOR.markers[1]
        above = ph.layout[:, 2] - ph.model.block.top(ph.layout[:, :2])
        assert ((m.marker_height[0] - 1e-9 <= above) & (above <= m.marker_height[1] + 1e-9)).all()
        np.testing.assert_allclose(ph.places[:, 2], ph.model.block.top(ph.places[:, :2]),
                                   atol=1e-9)
        column = ph.model.block.top(ph.centre[None, :2])[0] + ph.thickness
        assert 0 < ph.depth <= min(m.depth_m[1], m.column_share * column) + 1e-12
    assert {ph.cap for ph in phantoms} >= {Cap.DOME} and len({ph.cap for ph in phantoms}) >= 2


def test_a_block_is_drawn_from_its_seed_and_number_alone(phantoms) -> None:
    again = draw_mould(MOULDS, 3, 4, 2, 2)
    np.testing.assert_array_equal(again.layout, phantoms[4].layout)
    np.testing.assert_array_equal(again.places, phantoms[4].places)
    assert not np.array_equal(phantoms[3].layout[:3], phantoms[4].layout[:3])


def test_the_modulus_sends_the_centre_press_as_deep_as_drawn(phantoms) -> None:
    """Pressed along the inward normal at 7.5 N with the modulus found, the centre's tip goes
    the drawn depth: through the solid's own press (``predict``), and the law inverted
    (``stiffened``)."""
    ph = phantoms[0]
    solver: Solver = ph.model.factorise(np.ones(ph.model.elasticity.n_elements),
                                        FitSolidParams.poisson)
    at = ph.at()
    modulus = centre_modulus(ph, solver, at)
    resp = ph.model.respond(solver, ph.centre[None], ph.plan.protocol.contact_radius,
                            ph.model.probes(at))[0]
    inward = -ph.model.block.shape.closest(ph.centre[None])[1][0]
    _, tip = predict(resp, 7.5 * inward[None], modulus, ph.stiffening, ph.reach, at)
    assert np.linalg.norm(tip[0] - ph.centre) == pytest.approx(ph.depth, rel=1e-6)
    d_lin = 7.5 * 0.002 / modulus_for_depth(0.002, 0.02, 500.0)
    assert stiffened(np.array([d_lin]), 500.0)[0] == pytest.approx(0.02, rel=1e-9)


def test_simulate_moulds_writes_a_prior_states_file(tmp_path) -> None:
    """Two moulds through the CLI: a valid states file, each block padded to the prior's
    largest marker count with the tip last, every normal press moving its tip inward; its
    recording draws each shown sequence's cap under its markers."""
    out = tmp_path / "moulds.h5"
    res = CliRunner().invoke(cli, ["simulate", "--prior", "2", "--moulds", "--locations", "5",
                                   "--directions", "1", "--workers", "1", "--out", str(out)])
    assert res.exit_code == 0, res.output
    validate_states(out)
    entities = rrd_entities(out.with_suffix(".rrd"))
    moulds = [e for e in entities if e.endswith("/mould")]
    assert len(moulds) == 4 and all("Mesh3D" in entities[e] for e in moulds)
    assert all(e.replace("/mould", "/surface") in entities for e in moulds)
    with h5py.File(out) as f:
        points, valid = f["states/points"][()], f["states/valid"][()]
        step, seq = f["states/step"][()], f["states/sequence"][()]
        pushed = f["states/force_vector"][()]
        assert points.shape[1] == PRIOR.markers[1] + 1 and valid[:, -1].all()
        assert len(f["phantoms/modulus"]) == 2 and set(f["phantoms/cap"][()]) <= {0, 1, 2}
        assert f.attrs["source"] == "moulds"
    assert source_name(out) == "Moulds"                 # Table 2's name: not a lab's "Solid"
    for s in np.unique(seq):
        rest, last = points[(seq == s) & (step == 0)][0], points[(seq == s) & (step == 15)][0]
        assert np.linalg.norm(last[-1] - rest[-1]) > 5e-3      # the tip goes mm deep
        assert last[-1, 2] < rest[-1, 2]
    first = draw_mould(MOULDS, 0, 0, 5, 1)              # block 0, as the run drew it
    shape = first.model.block.shape
    for k, place in enumerate(first.places):            # each press recorded as applied:
        vector = pushed[(seq == k) & (step == 15)][0]   # along the inward normal (1 direction)
        np.testing.assert_allclose(vector / np.linalg.norm(vector),
                                   -shape.closest(place[None])[1][0], atol=1e-6)
    res = CliRunner().invoke(cli, ["-q", "fit-msm", str(out), "--out", str(tmp_path / "f.json"),
                                   "--no-rrd"])               # the MSM is flat: refused
    assert res.exit_code == 2 and "curved" in res.output and not (tmp_path / "f.json").exists()
    splits = tmp_path / "splits.json"                  # split as a simulator's: by place
    res = CliRunner().invoke(cli, ["-q", "split", str(out), "--out", str(splits), "--folds",
                                   "1", "--no-rrd"])
    assert res.exit_code == 0, res.output
    assert json.loads(splits.read_text())["group_by"] == "location"


@pytest.mark.parametrize("args, word", [(["--moulds"], "--prior N"),
                                        (["--prior", "2", "--moulds", "--shard", "0/2"],
                                         "--shard")])
def test_moulds_are_refused_without_a_prior_or_sharded(tmp_path, args, word) -> None:
    out = tmp_path / "m.h5"
    res = CliRunner().invoke(cli, ["simulate", *args, "--out", str(out), "--no-rrd"])
    assert res.exit_code == 2 and word in res.output and not out.exists()


@pytest.mark.parametrize("field, value", [("height", (0.02, 0.01)), ("ridge_share", 1.5),
                                          ("contact_radius", (0.0, 0.004))])
def test_a_prior_out_of_its_bounds_is_refused_by_name(field, value) -> None:
    """A range the wrong way round, a share beyond 1, a patch below the solid's least."""
    from core.errors import BadInput
    from sim.msm.mould_prior import MouldPrior

    with pytest.raises(BadInput, match=field):
        MouldPrior(**{field: value})

"""MSM data drawn from a prior: every draw inside the stated ranges, deterministic per block,
padded so a trainer masks what a phantom lacks, sharded and merged to the same bytes."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from data_schema.states import validate_states
from pipeline.cli import cli
from sim.msm.msm import MSM
from sim.msm.msm_prior import PRIOR, draw_phantom
from sim.msm.msm_prior_data import PriorRun, simulate_prior
from sim.msm.msm_sampling import contact_masses

BLOCKS = range(24)


@pytest.fixture(scope="module")
def phantoms():
    return [draw_phantom(PRIOR, 7, b, 3, 2) for b in BLOCKS]


def test_every_draw_lies_in_the_priors_ranges(phantoms) -> None:
    p = PRIOR
    for ph in phantoms:
        size = np.array(ph.params.footprint)
        assert p.k_between[0] <= ph.params.k_between <= p.k_between[1]
        assert p.k_fixed[0] <= ph.params.k_fixed <= p.k_fixed[1]
        assert p.contact_radius[0] <= ph.protocol.contact_radius <= p.contact_radius[1]
        assert p.max_angle_deg[0] <= ph.protocol.max_angle_deg <= p.max_angle_deg[1]
        assert ((p.side[0] <= size) & (size <= p.side[1])).all()
        assert max(ph.params.n, ph.params.n_y) <= p.masses
        assert p.markers[0] <= len(ph.layout) <= p.markers[1]
        xy = ph.layout[:, :2]
        assert (xy >= p.edge - 1e-12).all() and (xy <= size - p.edge + 1e-12).all()
        gaps = np.linalg.norm(xy[:, None] - xy[None], axis=2) + np.eye(len(xy))
        nearest = gaps.min(axis=1)
        if ph.scattered:                 # a scattered set: none closer than its pitch
            assert nearest.min() >= ph.pitch - 1e-12
        else:                            # a grid: every marker's neighbour one pitch away
            np.testing.assert_allclose(nearest, ph.pitch, rtol=1e-9)
        assert (ph.layout[:, 2] == 0).all()
        assert ph.protocol.fmax == 7.5 and ph.protocol.step_n == 0.5


def test_the_draws_span_the_layouts_and_springs_labs_have(phantoms) -> None:
    """Both kinds of layout, and springs on both sides of the twin's fits (165 / 7 N/m)."""
    assert {ph.scattered for ph in phantoms} == {True, False}
    kb = [ph.params.k_between for ph in phantoms]
    kf = [ph.params.k_fixed for ph in phantoms]
    assert min(kb) < 165 < max(kb) and min(kf) < 7 < max(kf)


def test_a_block_is_drawn_from_its_seed_and_number_alone(phantoms) -> None:
    again = draw_phantom(PRIOR, 7, 5, 3, 2)
    np.testing.assert_array_equal(again.layout, phantoms[5].layout)
    assert again.params == phantoms[5].params and again.protocol == phantoms[5].protocol
    other = draw_phantom(PRIOR, 8, 5, 3, 2)
    assert other.params != phantoms[5].params


def test_impossible_ranges_are_refused() -> None:
    from core.errors import BadInput

    crowded = replace(PRIOR, side=(0.06, 0.06), pitch=(0.025, 0.025), markers=(60, 64))
    with pytest.raises(BadInput, match="no phantom"):       # 60 markers 25 mm apart on 6 cm
        draw_phantom(crowded, 0, 0, 1, 1)
    with pytest.raises(BadInput, match=r"^k_fixed \(5, 1\): not a range"):
        replace(PRIOR, k_fixed=(5.0, 1.0))


@pytest.mark.parametrize(("change", "words"), [
    ({"k_between": (0.0, 420.0)}, "k_between 0.0 N/m: must be in [1, 100000] N/m"),
    ({"markers": (3, 64)}, "markers 3: must be >= 4"),
    ({"side": (0.06, 3.0)}, "side 3.0 m: must be in (0, 2] m"),
    ({"max_angle_deg": (0.0, 95.0)}, "max_angle_deg 95.0 deg: must be in [0, 90] deg"),
    ({"missing": (0.0, 1.0)}, "missing 1.0: must be in [0, 1)"),
    ({"pitch": (0.0, 0.025)}, "pitch 0.0 m: must be > 0 m"),
])
def test_a_range_out_of_its_bound_is_refused_in_one_line(change, words) -> None:
    """The prior's ranges are checked by their bounds, as every setting is, when it is
    made."""
    from core.errors import BadInput

    with pytest.raises(BadInput) as refused:
        replace(PRIOR, **change)
    assert str(refused.value).startswith(words) and "\n" not in str(refused.value)


@pytest.mark.parametrize(("counts", "option"), [((0, 2, 1), "--prior 0: must be >= 1"),
                                                ((3, 0, 1), "--locations 0: must be >= 1"),
                                                ((3, 2, -1), "--directions -1: must be >= 1")])
def test_a_run_of_no_phantoms_is_refused_naming_the_option_that_sets_it(counts, option):
    """A library caller is refused in the words of ``pipeline simulate``'s option (the count of
    phantoms is ``--prior``), as the command line refuses it."""
    from core.errors import BadInput

    with pytest.raises(BadInput) as refused:
        simulate_prior(PriorRun(PRIOR, *counts, seed=0))
    assert str(refused.value) == option


def test_the_command_line_refuses_no_places_in_one_line(tmp_path) -> None:
    res = CliRunner().invoke(cli, ["-q", "simulate", "--prior", "2", "--locations", "0",
                                   "--out", str(tmp_path / "x.h5")])
    assert res.exit_code == 2 and not (tmp_path / "x.h5").exists()
    assert res.stderr.strip() == "error: --locations 0: must be >= 1"


def _simulate(out: Path, *extra: str) -> None:
    res = CliRunner().invoke(cli, ["-q", "simulate", "--prior", "3", "--locations", "2",
                                   "--directions", "1", "--seed", "4", "--workers", "1",
                                   "--out", str(out), *extra])
    assert res.exit_code == 0, res.output + res.stderr


@pytest.fixture(scope="module")
def prior_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("prior") / "prior.h5"
    _simulate(out)
    return out


def test_the_file_pads_each_phantom_to_the_largest_count_the_tip_last(prior_file) -> None:
    validate_states(prior_file)
    with h5py.File(prior_file) as f:
        points, valid = f["states/points"][()], f["states/valid"][()]
        tip, block, markers = f["states/tip"][()], f["states/phantom"][()], \
            f["phantoms/markers"][()]
        step, seq = f["states/step"][()], f["states/sequence"][()]
    assert points.shape[1] == PRIOR.markers[1] + 1 and len(markers) == 3
    np.testing.assert_array_equal(points[:, -1], tip)
    assert valid[:, -1].all()
    for b, n in enumerate(markers):
        rows = block == b
        assert not valid[rows, n:-1].any() and np.isnan(points[rows, n:-1]).all()
        assert valid[rows, :n].mean() > 1 - PRIOR.missing[1] - 0.05
    assert len(np.unique(seq)) == 3 * 2 * 1 and set(step) == set(range(16))


def test_a_phantoms_states_are_its_msm_at_its_markers(prior_file) -> None:
    """At rest each marker sits where the phantom's layout puts it and the tip on the surface;
    pressed along the normal, the tip goes down by more than any marker."""
    with h5py.File(prior_file) as f:
        points, valid, step = f["states/points"][()], f["states/valid"][()], \
            f["states/step"][()]
        block, mass = f["states/phantom"][()], f["states/mass"][()]
    for b in range(3):
        ph = draw_phantom(PRIOR, 4, b, 2, 1)
        n = len(ph.layout)
        rest = np.flatnonzero((block == b) & (step == 0))
        for r in rest:
            seen = valid[r, :n]
            np.testing.assert_allclose(points[r, :n][seen], ph.layout[seen], atol=1e-7)
            model = MSM(ph.params)
            patch = contact_masses(model, model.rest[mass[r], :2], ph.protocol.contact_radius)
            np.testing.assert_allclose(points[r, -1], model.rest[patch].mean(axis=0),
                                       atol=1e-7)
        top = np.flatnonzero((block == b) & (step == 15))
        for r in top:
            assert points[r, -1, 2] < np.nanmin(points[r, :n, 2])


def test_shards_merge_to_the_bytes_of_one_run(prior_file, tmp_path) -> None:
    parts = [tmp_path / f"part{i}.h5" for i in range(2)]
    for i, part in enumerate(parts):
        _simulate(part, "--shard", f"{i}/2", "--no-rrd")
    merged = tmp_path / "merged.h5"
    res = CliRunner().invoke(cli, ["-q", "simulate", "--merge", *map(str, parts), "--out",
                                   str(merged), "--no-rrd"])
    assert res.exit_code == 0, res.output + res.stderr
    with h5py.File(prior_file) as a, h5py.File(merged) as b:
        names: list[str] = []
        a.visititems(lambda n, o: names.append(n) if isinstance(o, h5py.Dataset) else None)
        for name in names:
            np.testing.assert_array_equal(a[name][()], b[name][()], err_msg=name)
        assert a.attrs["protocol"] == b.attrs["protocol"]


@pytest.mark.parametrize("extra, named", [(("--k-between", "120"), "--k-between"),
                                           (("--size", "120x80"), "--size"),
                                           (("--fmax", "6"), "--fmax")])
def test_what_the_prior_draws_cannot_be_given(tmp_path, extra, named) -> None:
    res = CliRunner().invoke(cli, ["-q", "simulate", "--prior", "2", "--out",
                                   str(tmp_path / "x.h5"), *extra])
    assert res.exit_code == 2 and named in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and not (tmp_path / "x.h5").exists()


def test_the_recording_shows_phantoms_of_the_prior(prior_file) -> None:
    from core.recording import rrd_entities

    entities = rrd_entities(prior_file.with_suffix(".rrd"))
    surfaces = [e for e in entities if e.endswith("/surface")]
    assert surfaces and all("Points3D" in entities[e] for e in surfaces)

"""A stiffness map: the MSM stiffer in places, its derivatives, and the map fitted back from
states the MSM made with a known map (`pipeline fit-msm --map`, `simulate --params`)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from core.recording import rrd_entities
from data_schema.json_docs import MSM_PARAMS
from pipeline.cli import cli
from sim.msm.msm import MSM, MSMError, MSMParams
from sim.msm.msm_map_fit import MapResult, fit_map, place_centres, stiffest_region
from sim.msm.msm_measured import read_measured
from sim.msm.msm_protocol import Protocol
from sim.msm.msm_regions import finest_grid, mass_factors, parse_regions
from sim.msm.msm_sensitivity import mass_regions, state_derivatives
from sim.msm.msm_static import simulate_sequence
from sim.msm.simulate_stage import generate

SMALL = MSMParams(n=12, size=0.1)          # 9 mm between masses: quick solves
DOWN = np.array([0.0, 0.0, -1.0])
STIFF = ((1.0, 1.0), (1.0, 3.0))           # the region of large x and y 3x as stiff


def _depth(params: MSMParams, node: int, fmax: float = 0.2) -> float:
    """How far the pressed mass sinks under ``fmax`` N straight down."""
    model = MSM(params)
    states = simulate_sequence(model, node, DOWN, steps=2, fmax=fmax)
    return float(model.rest[node, 2] - states[-1][node, 2])


def test_a_map_of_one_factor_is_the_uniform_msm_with_scaled_constants():
    """f everywhere = both spring kinds times f: the same equilibria, exactly."""
    node = MSM(SMALL).node(5, 6)
    mapped = simulate_sequence(MSM(replace(SMALL, stiffness_map=((2.5,),))), node, DOWN, 3, 2.0)
    scaled = simulate_sequence(MSM(replace(SMALL, k_between=SMALL.k_between * 2.5,
                                           k_fixed=SMALL.k_fixed * 2.5)), node, DOWN, 3, 2.0)
    np.testing.assert_allclose(mapped, scaled, atol=1e-9)


def test_a_stiffer_region_moves_less_under_the_same_press():
    """Mirror places on the square grid: the one in the 3x region sinks less, by no more than
    the factor (a region's neighbours share the load), and more than a whole 3x surface."""
    model = MSM(SMALL)
    stiff, soft = model.node(8, 8), model.node(3, 3)          # mirror images about the centre
    mapped = replace(SMALL, stiffness_map=STIFF)
    d_stiff, d_soft = _depth(mapped, stiff), _depth(mapped, soft)
    whole = _depth(replace(SMALL, stiffness_map=((3.0,),)), stiff)
    assert d_stiff < d_soft / 1.5
    assert whole < d_stiff
    assert d_soft == pytest.approx(_depth(SMALL, soft), rel=0.1)   # far from the stiff region


def test_masses_take_their_region_s_factor():
    xy = np.array([[0.0, 0.0], [0.049, 0.051], [0.051, 0.049], [0.1, 0.1]])
    np.testing.assert_array_equal(mass_factors(xy, (0.1, 0.1), ((1.0, 2.0), (3.0, 4.0))),
                                  [1.0, 3.0, 2.0, 4.0])


def test_the_derivatives_match_re_solved_equilibria():
    """The implicit derivative of the equilibrium against central differences of solves."""
    table = np.array([[1.0, 2.0, 1.0], [0.7, 1.0, 1.5]])
    base = MSMParams(n=16, size=0.05, n_y=10, size_y=0.03)

    def solve(factors: np.ndarray) -> np.ndarray:
        model = MSM(replace(base, stiffness_map=factors.tolist()))
        return simulate_sequence(model, model.node(5, 7), np.array([0.2, 0.0, -1.0]), 3, 2.0,
                                 tol=1e-10)[-1]

    model = MSM(replace(base, stiffness_map=table.tolist()))
    exact = state_derivatives(model, solve(table), mass_regions(model, table.shape), 6)
    h = 1e-5
    for r in range(6):
        up, down = table.ravel().copy(), table.ravel().copy()
        up[r] *= np.exp(h)
        down[r] *= np.exp(-h)
        numeric = (solve(up.reshape(2, 3)) - solve(down.reshape(2, 3))) / (2 * h)
        assert np.abs(numeric - exact[r]).max() <= 1e-6 * np.abs(numeric).max() + 1e-12


@pytest.mark.parametrize("bad", [((1.0, -2.0),), ((1.0, 2.0), (1.0,)), (), ((np.nan,),)])
def test_a_bad_map_is_refused_in_one_line(bad):
    with pytest.raises(MSMError, match="stiffness_map"):
        MSMParams(stiffness_map=bad)


@pytest.mark.parametrize("text", ["3", "0x3", "3x3x3", "9x9", "a"])
def test_malformed_regions_are_refused(text):
    with pytest.raises(Exception, match="--regions"):
        parse_regions(text)


def _grid_of_places(*mm: float) -> np.ndarray:
    """Places (K, 2) in m on the grid of the given x = y positions (mm)."""
    return np.array([(x, y) for y in mm for x in mm]) * 1e-3


@pytest.mark.parametrize("places, footprint, shape", [
    (_grid_of_places(20, 40, 60, 80), (0.1, 0.1), (4, 4)),         # synth --locations 4x4
    (_grid_of_places(20, 50, 80), (0.1, 0.1), (3, 3)),             # synth --locations 3x3
    (_grid_of_places(19.8, 40.2, 59.9, 80.1), (0.1, 0.1), (4, 4)),  # the tips' noise: no 5x5
    (np.array([[0.05, 0.05]]), (0.1, 0.1), (1, 1)),                # one place: uniform
    (np.array([[0.02, 0.05], [0.08, 0.05]]), (0.1, 0.1), (1, 2)),   # two along x
    (np.array([[0.02, 0.05], [0.08, 0.05]]) + 0.025, (0.1, 0.1), (1, 1)),  # off the middles
])
def test_the_finest_grid_holds_a_place_in_every_region_s_middle(places, footprint, shape):
    assert finest_grid(places, footprint) == shape


def test_places_are_the_states_file_s_locations_centred_on_their_tips(tmp_path):
    """Each MSM location (a loaded mass) is a place; a press twice is the same place; the
    file's ids decide, not how near the tips rest (one id for all: one place at their mean)."""
    path = _made(tmp_path / "flat.h5", None)
    sequences, _ = read_measured(path)
    with h5py.File(path) as f:
        locations = set(f["states/location"][()].tolist())
    centres = place_centres(sequences + sequences)        # each press twice: the same places
    assert len(centres) == len(place_centres(sequences)) == len(locations) == len(
        {tuple(np.round(s.rest[s.is_tip][0, :2], 6)) for s in sequences})
    tips = np.array([s.rest[s.is_tip][0, :2] for s in sequences])
    one = place_centres([replace(s, location=7) for s in sequences])
    np.testing.assert_allclose(one, [tips.mean(axis=0)])


def _map(factors: list[list[float]], held: tuple[tuple[int, int], ...] = ()) -> MapResult:
    rows, cols = len(factors), len(factors[0])
    sd = [[None if (i, j) in held else 0.01 for j in range(cols)] for i in range(rows)]
    return MapResult((rows, cols), factors, sd, [[[]] * cols] * rows, rows * cols, 1.0, [],
                     0.0, 0.0, 1)


def test_the_peak_lies_between_regions_that_share_a_lump():
    """Two neighbouring regions equally stiff above a flat map: the peak halfway between their
    centres; a held region (no press) is never the stiffest; a lone stiff region is its own
    peak."""
    flat = [[1.0] * 4 for _ in range(4)]
    shared = [row[:] for row in flat]
    shared[1][1] = shared[1][2] = 1.2                      # y band 1, x bands 1 and 2
    top = stiffest_region(_map(shared), (0.1, 0.1))
    assert top["peak_mm"] == pytest.approx([50.0, 37.5])
    assert top["centre_mm"] in ([37.5, 37.5], [62.5, 37.5])
    held = [row[:] for row in flat]
    held[0][0], held[3][3] = 5.0, 1.3
    top = stiffest_region(_map(held, held=((0, 0),)), (0.1, 0.1))
    assert top["region"] == [3, 3] and top["peak_mm"] == pytest.approx([87.5, 87.5])
    assert stiffest_region(_map(flat, held=tuple((i, j) for i in range(4) for j in range(4))),
                           (0.1, 0.1)) is None


# -- the map fitted back ---------------------------------------------------------------------

PROTOCOL = Protocol(locations=12, directions=1, steps=3, fmax=1.0, seed=2)


def _made(path: Path, stiffness_map, protocol: Protocol = PROTOCOL) -> Path:
    """MSM states made on the small grid with a known map."""
    generate(path, protocol, replace(SMALL, stiffness_map=stiffness_map))
    return path


def test_the_fit_finds_the_stiff_region_it_was_made_with(tmp_path):
    sequences, grid = read_measured(_made(tmp_path / "stiff.h5", STIFF))
    found = fit_map(sequences, replace(grid, stiffness_map=None), (2, 2))
    assert all(found.informed_by[i][j] for i in range(2) for j in range(2))
    np.testing.assert_allclose(found.factors, STIFF, rtol=0.05)
    assert found.mean_distance_m < 0.2 * found.uniform_distance_m
    assert all(sd is not None and sd >= 0 for row in found.sd for sd in row)
    assert found.note == ""


def test_a_uniform_surface_comes_out_flat(tmp_path):
    sequences, grid = read_measured(_made(tmp_path / "flat.h5", None))
    found = fit_map(sequences, grid, (3, 3))
    factors = np.asarray(found.factors)
    assert np.abs(factors / factors.mean() - 1).max() < 0.02


def test_one_place_cannot_tell_regions_apart(tmp_path):
    one = replace(PROTOCOL, locations=1, directions=3)
    sequences, grid = read_measured(_made(tmp_path / "one.h5", None, one))
    found = fit_map(sequences, grid, (3, 3))
    assert found.factors == [[1.0] * 3] * 3
    assert "cannot tell" in found.note and "uniform" in found.note
    assert found.places == 1
    found = fit_map(sequences, grid)                      # the finest grid one place covers
    assert found.shape == (1, 1) and found.factors == [[1.0]] and found.stiffest is None
    assert "cannot tell" in found.note and "uniform" in found.note


def test_cli_map_round_trips_through_simulate(tmp_path):
    """fit-msm --map writes the map into the params JSON; simulate --params makes MSM data
    that carries it; a file without a map simulates uniform."""
    made = _made(tmp_path / "stiff.h5", STIFF)
    params = tmp_path / "params.json"
    result = CliRunner().invoke(cli, ["fit-msm", str(made), "--map", "--regions", "2x2",
                                      "--workers", "1", "--out", str(params)])
    assert result.exit_code == 0, result.output
    assert "stiffness map 2x2" in result.output
    doc = json.loads(params.read_text())
    assert doc["schema_version"] == MSM_PARAMS.version
    np.testing.assert_allclose(doc["msm_params"]["stiffness_map"], STIFF, rtol=0.1)
    assert doc["map"]["stiffest"]["region"] == [1, 1]          # STIFF's 3x region
    assert doc["map"]["stiffest"]["centre_mm"] == pytest.approx([75.0, 75.0])
    assert doc["map"]["stiffest"]["peak_mm"] == pytest.approx([75.0, 75.0], abs=2.0)
    assert "stiffest region centred at (75, 75) mm" in result.output
    assert "map/regions" in " ".join(rrd_entities(params.with_suffix(".rrd")))
    out = tmp_path / "again.h5"
    result = CliRunner().invoke(cli, ["simulate", "--params", str(params), "--out", str(out),
                                      "--locations", "2", "--directions", "1", "--steps", "2",
                                      "--workers", "1", "--no-rrd"])
    assert result.exit_code == 0, result.output
    with h5py.File(out) as f:
        carried = json.loads(f.attrs["msm_params"])["stiffness_map"]
    np.testing.assert_allclose(carried, doc["msm_params"]["stiffness_map"])


def test_cli_refusals_are_one_line(tmp_path):
    made = _made(tmp_path / "stiff.h5", None, replace(PROTOCOL, locations=2))
    for args in (["--map", "--regions", "3by3"], ["--regions", "2x2"]):
        result = CliRunner().invoke(cli, ["fit-msm", str(made), "--workers", "1", *args])
        assert result.exit_code == 2, result.output
        assert "--regions" in result.output and len(result.output.strip().splitlines()) == 1


def test_region_of_each_mass_is_its_factor_s():
    model = MSM(replace(SMALL, stiffness_map=STIFF))
    regions = mass_regions(model, (2, 2))
    factors = np.asarray(STIFF).ravel()[regions]
    np.testing.assert_allclose(model.k_fixed[:, 0], SMALL.k_fixed * factors)


@pytest.mark.slow
def test_the_uniform_twin_comes_out_flat(tmp_path):
    """The twin without an inclusion, 9 places pressed twice: every region within +-20 % of
    the map's mean (the target of issue 49)."""
    folder = tmp_path / "uniform"
    folder.mkdir()
    for args in (("synth", folder / "s", "--seed", "31", "--locations", "3x3", "--repeats",
                  "2", "--no-rrd"),
                 ("ingest", folder / "s", "--out", folder / "s.mcap", "--no-rrd"),
                 ("sync", folder / "s.mcap", "--out", folder / "synced.h5", "--no-rrd"),
                 ("extract", folder / "synced.h5", "--out", folder / "states.h5", "--no-rrd")):
        res = CliRunner().invoke(cli, ["-q", *map(str, args)])
        assert res.exit_code == 0, res.output
    params = folder / "params.json"
    res = CliRunner().invoke(cli, ["fit-msm", str(folder / "states.h5"), "--map",  # every press
                                   "--out", str(params), "--no-rrd"])
    assert res.exit_code == 0, res.output
    found = json.loads(params.read_text())["map"]
    assert found["shape"] == [3, 3]                       # the finest grid 3x3 places cover
    factors = np.asarray(found["factors"])
    assert np.abs(factors / factors.mean() - 1).max() <= 0.2, factors

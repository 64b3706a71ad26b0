"""The MSM on any rectangle: the grid sized to a footprint, its kernels against analytic truth
(affine stretches, the transposed rectangle, point symmetry), sampling, the fit recovering known
constants, and `pipeline simulate` / `fit-msm` sized to a lab's footprint."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner
from helpers.msm_reference import forces_by_edge_loop

from pipeline.cli import cli
from sim.msm.msm import MSM, MSMParams, max_eigenfrequency, unit
from sim.msm.msm_dataset import file_attrs, write_states
from sim.msm.msm_fit import fit_msm, still
from sim.msm.msm_grid import PAPER_SPACING_M, grid_params
from sim.msm.msm_measured import read_measured
from sim.msm.msm_protocol import Protocol, draw_plan
from sim.msm.msm_sampling import contact_masses, sample_at
from sim.msm.msm_static import simulate_sequence
from sim.msm.simulate_stage import generate

RECT = MSMParams(n=9, size=0.024, n_y=5, size_y=0.014)     # 3.0 x 3.5 mm spacing: not square


def _model(cols: int = 9, rows: int = 5, length: float = 0.024, width: float = 0.014) -> MSM:
    return MSM(MSMParams(n=cols, size=length, n_y=rows, size_y=width))


# -- the grid ----------------------------------------------------------------------------------

@pytest.mark.parametrize("size,grid", [((0.1, 0.1), (32, 32)), ((0.12, 0.07), (38, 23)),
                                       ((0.15, 0.08), (48, 26))])
def test_the_grid_keeps_the_paper_spacing_and_covers_the_footprint(size, grid):
    """round(L / h) + 1 masses per axis at the paper's h = 100/31 mm (120 mm / h = 37.2,
    70 mm / h = 21.7, 150 mm / h = 46.5 rounds up), spaced L / (n - 1): exactly [0, L] x [0, W]."""
    params = grid_params(size)
    assert (params.n, params.n_y) == grid
    model = MSM(params)
    assert model.N == grid[0] * grid[1]
    np.testing.assert_allclose(model.rest.min(axis=0), [0, 0, 0], atol=1e-15)
    np.testing.assert_allclose(model.rest.max(axis=0), [*size, 0], rtol=1e-14)
    for h, side, n in ((params.spacing_x, size[0], grid[0]), (params.spacing_y, size[1],
                                                               grid[1])):
        assert h == pytest.approx(side / (n - 1), rel=1e-14)
        assert abs(h - PAPER_SPACING_M) <= PAPER_SPACING_M / (n - 1)   # the nearest such h
    if size == (0.1, 0.1):
        assert params == MSMParams()                             # the paper's, exactly


def test_spacing_option_sets_the_masses_per_axis():
    params = grid_params((0.15, 0.08), spacing=0.005)
    assert (params.n, params.n_y) == (31, 17)                  # 150 / 5 + 1, 80 / 5 + 1
    assert params.spacing_x == pytest.approx(0.005) and params.spacing_y == pytest.approx(0.005)


def test_geometry_of_a_rectangle():
    model = MSM(RECT)
    hx, hy = 0.024 / 8, 0.014 / 4
    assert model.N == 45 and (model.rows, model.cols) == (5, 9)
    np.testing.assert_allclose(model.rest[model.node(4, 8)], [0.024, 0.014, 0.0], rtol=1e-14)
    np.testing.assert_allclose(model.rest[model.node(3, 2)], [2 * hx, 3 * hy, 0.0], rtol=1e-14)
    edges = model.edges()
    assert len(edges) == 5 * 8 + 4 * 9 + 4 * 8                  # rows, columns, one diagonal
    d = model.rest[edges[:, 1]] - model.rest[edges[:, 0]]
    lengths = {tuple(np.round(v[:2] * 1e6)) for v in d}
    assert lengths == {(3000.0, 0.0), (0.0, 3500.0), (3000.0, 3500.0)}
    tri = model.triangles()
    assert len(tri) == 2 * 4 * 8
    a, b, c = (model.rest[tri[:, k], :2] for k in range(3))
    area = 0.5 * np.abs((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    assert area.sum() == pytest.approx(0.024 * 0.014, rel=1e-12)   # they tile the footprint
    assert np.allclose(area, hx * hy / 2)


def test_old_square_record_reads_as_the_square():
    assert MSMParams(**{"n": 20, "size": 0.05}) == MSMParams(n=20, size=0.05, n_y=20,
                                                             size_y=0.05)
    assert MSMParams().as_dict()["n_y"] == 32 and MSMParams().footprint == (0.1, 0.1)


# -- kernels against analytic truth --------------------------------------------------------------

def _affine(model: MSM, ax: float, ay: float) -> np.ndarray:
    return model.rest * [1 + ax, 1 + ay, 1]


def test_rest_has_no_force_and_an_affine_stretch_has_its_analytic_energy():
    """x -> (1 + a) x, y -> (1 + b) y: every row spring stretches by a h_x, every column spring
    by b h_y, every diagonal to hypot((1 + a) h_x, (1 + b) h_y); inside, each mass's springs
    pull in opposite pairs, so only its fixed spring is left."""
    model = MSM(replace(RECT, k_between=70.0, k_fixed=20.0))
    zero = np.zeros((model.N, 3))
    assert np.abs(model.forces(model.rest, zero)).max() < 1e-12       # rounding of h only
    a, b = 0.03, -0.02
    hx, hy = RECT.spacing_x, RECT.spacing_y
    x = _affine(model, a, b)
    energy, f = model.energy_forces(x, zero)
    rows, cols = 5, 9
    diag = np.hypot((1 + a) * hx, (1 + b) * hy) - np.hypot(hx, hy)
    springs = (rows * (cols - 1) * (a * hx) ** 2 + (rows - 1) * cols * (b * hy) ** 2
               + (rows - 1) * (cols - 1) * diag ** 2)
    fixed = ((x - model.rest) ** 2).sum()
    assert energy == pytest.approx(0.5 * 70.0 * springs + 0.5 * 20.0 * fixed, rel=1e-12)
    inside = np.array([model.node(i, j) for i in range(1, rows - 1) for j in range(1, cols - 1)])
    np.testing.assert_allclose(f[inside], -20.0 * (x - model.rest)[inside], atol=1e-12)
    np.testing.assert_allclose(f.sum(axis=0), -20.0 * (x - model.rest).sum(axis=0), atol=1e-12)


@pytest.mark.parametrize("cols,rows", [(9, 5), (5, 9)])
def test_forces_energy_gradient_and_tangent_band_on_a_rectangle(cols, rows):
    """Forces against an edge loop and the energy's gradient; the band (masses numbered along
    the shorter side: half-bandwidth 3 (5 + 1) + 2 both ways) against the force Jacobian by
    finite differences."""
    model = _model(cols, rows, 0.003 * (cols - 1), 0.0035 * (rows - 1))
    rng = np.random.default_rng(2)
    x = model.rest * 1.04 + rng.normal(0, 2e-4, model.rest.shape)
    f_ext = model.load(7, [0.2, -0.1, -1.0])
    energy, f = model.energy_forces(x, f_ext)
    np.testing.assert_allclose(f, forces_by_edge_loop(model, x, f_ext), atol=1e-12)
    eps = 1e-7
    ab, bw = model.stiffness_band(x), model.band_width
    assert bw == 20
    band = np.zeros((3 * model.N, 3 * model.N))
    for off in range(bw + 1):
        i = np.arange(band.shape[0] - off)
        band[i, i + off] = band[i + off, i] = ab[bw - off, off:]
    order = np.arange(3 * model.N) if model.band_order is None else model.band_order
    assert (model.band_order is None) == (cols < rows)
    k = np.empty_like(band)
    k[np.ix_(order, order)] = band                      # back to the masses' own order
    for _ in range(3):
        v = rng.normal(size=x.shape)
        slope = (model.energy_forces(x + eps * v, f_ext)[0]
                 - model.energy_forces(x - eps * v, f_ext)[0]) / (2 * eps)
        assert slope == pytest.approx(-(f * v).sum(), rel=1e-6)
        jv = -(model.forces(x + eps * v, 0 * x) - model.forces(x - eps * v, 0 * x)) / (2 * eps)
        assert np.allclose(jv.ravel(), k @ v.ravel(), atol=1e-5 * np.abs(k).max())
    # the stability limit's largest eigenvalue, against the dense matrix's
    top = np.linalg.eigvalsh(k).max()
    assert max_eigenfrequency(model, x) ** 2 * model.params.mass == pytest.approx(top, rel=1e-9)


def test_the_transposed_rectangle_gives_the_transposed_response():
    """Swapping x and y maps a cols x rows grid onto a rows x cols one and every spring family
    onto itself (the diagonal (i, j)-(i + 1, j + 1) included), so a load at (i, j) on one is a
    load at (j, i) on the other with fx, fy swapped: the same equilibria, transposed."""
    a = _model(9, 5, 0.024, 0.014)
    b = _model(5, 9, 0.014, 0.024)
    force = unit([0.3, -0.5, -1.0])
    sa = simulate_sequence(a, a.node(1, 6), force, steps=3, fmax=3.0, tol=1e-10)
    sb = simulate_sequence(b, b.node(6, 1), force[[1, 0, 2]], steps=3, fmax=3.0, tol=1e-10)
    ua = (sa - a.rest).reshape(4, 5, 9, 3)
    ub = (sb - b.rest).reshape(4, 9, 5, 3).transpose(0, 2, 1, 3)[..., [1, 0, 2]]
    assert np.abs(ua).max() > 1e-3                    # millimetres moved
    np.testing.assert_allclose(ua, ub, atol=1e-10)


def test_a_centred_normal_load_is_point_symmetric_on_a_symmetric_rectangle():
    """Odd masses both ways put mass (3, 7) at the centre of a 15 x 7 grid; a half-turn about
    it maps the grid, its borders and every spring family onto themselves, so the response to
    a normal load there is exactly point symmetric (u(-r) = (-u_x, -u_y, u_z)(r))."""
    model = _model(15, 7, 0.042, 0.024)
    states = simulate_sequence(model, model.node(3, 7), [0, 0, -1], steps=2, fmax=2.0,
                               tol=1e-10)
    for x in states[1:]:
        u = (x - model.rest).reshape(7, 15, 3)
        turned = u[::-1, ::-1] * [-1, -1, 1]
        np.testing.assert_allclose(u, turned, atol=1e-10)
        assert np.abs(u[..., 2]).argmax() == 3 * 15 + 7        # the loaded mass goes deepest


# -- sampling ----------------------------------------------------------------------------------

def test_bilinear_sampling_on_a_rectangle_is_exact_for_a_linear_field():
    model = MSM(RECT)
    hx, hy = RECT.spacing_x, RECT.spacing_y
    points = np.array([[2.25 * hx, 3.5 * hy], [7.9 * hx, 0.1 * hy], [0.024, 0.014]])
    s = sample_at(model, points)
    assert sorted(s.masses[0].tolist()) == sorted([3 * 9 + 2, 3 * 9 + 3, 4 * 9 + 2, 4 * 9 + 3])
    disp = np.zeros((model.N, 3))
    disp[:, 2] = 2 * model.rest[:, 0] - 3 * model.rest[:, 1]
    np.testing.assert_allclose(s.displace(disp)[:, 2], 2 * points[:, 0] - 3 * points[:, 1],
                               atol=1e-15)
    centre = model.rest[model.node(2, 4), :2]
    assert len(contact_masses(model, centre, 1.01 * hx)) == 3           # hx < hy: the row only
    assert len(contact_masses(model, centre, 1.01 * hy)) == 5


# -- the fit on a rectangle ----------------------------------------------------------------------

GRID = grid_params((0.048, 0.03))                              # 16 x 10 masses
TRUE = replace(GRID, k_between=80.0, k_fixed=30.0)
SCATTERED = np.array([[0.007, 0.006, 0], [0.021, 0.004, 0], [0.043, 0.008, 0],
                      [0.012, 0.017, 0], [0.031, 0.014, 0], [0.046, 0.022, 0],
                      [0.005, 0.026, 0], [0.026, 0.025, 0]])
NAMES = [f"M{k:02d}" for k in range(len(SCATTERED))]


def _lab_file(path: Path, params: MSMParams = TRUE, locations: int = 3) -> Path:
    """Lab states as extract writes them, made by the MSM on a 48 x 30 mm rectangle: 8
    scattered named markers, the tip last, normal presses among them, no force vectors, and
    the footprint the frame uses (``footprint_m``)."""
    protocol = Protocol(locations=locations, directions=1, steps=3, fmax=3.0, seed=3)
    _, arrays = generate(path.with_suffix(".msm.h5"), protocol, params, layout=SCATTERED,
                         point_names=[*NAMES, "tip"])
    lab = {k: v for k, v in arrays.items() if k not in ("states/force_vector", "states/mass")}
    attrs = file_attrs(draw_plan(protocol, MSM(params).N), params, 1e-6, {"stage": "test"},
                       None)
    attrs.update(source="lab", point_names=json.dumps([*NAMES, "tip"]))
    del attrs["msm_params"], attrs["protocol"]
    write_states(path, lab, attrs)
    return path


def test_fit_recovers_the_constants_of_a_rectangular_msm_file(tmp_path):
    """An MSM file carries its grid (16 x 10 over 48 x 30 mm) and its force vectors: the fit
    there is exact up to float32 storage."""
    _lab_file(tmp_path / "lab.h5")
    sequences, params = read_measured(tmp_path / "lab.msm.h5")
    assert params == TRUE
    result = fit_msm(sequences, replace(params, k_between=100.0, k_fixed=21.0),
                     start=(100.0, 21.0), rel_tol=1e-3)
    assert result.k_between == pytest.approx(80.0, rel=0.01)
    assert result.k_fixed == pytest.approx(30.0, rel=0.01)
    assert result.mean_distance_m < 1e-6 < result.start_distance_m
    assert result.grid == "48 x 30 mm of 16 x 10 masses"


def test_fit_on_lab_states_sizes_the_grid_to_their_footprint(tmp_path):
    """Lab states name no grid: it is sized to their footprint_m. Their loads point along the
    tip's motion (a lab has only the force's magnitude), a degree or so off the MSM's normal
    loads near the borders, so the fit is close, not exact."""
    sequences, params = read_measured(_lab_file(tmp_path / "lab.h5"))
    assert params == GRID                                    # from footprint_m, not the paper's
    assert sequences[0].is_tip.tolist() == [False] * 8 + [True]
    result = fit_msm(sequences, params, start=(100.0, 21.0), rel_tol=1e-3)
    assert result.k_between == pytest.approx(80.0, rel=0.02)
    assert result.k_fixed == pytest.approx(30.0, rel=0.02)
    assert result.mean_distance_m < 0.02 * still(sequences, False).pooled


def test_spacing_sizes_a_lab_grid_and_is_refused_for_an_msm_file(tmp_path):
    lab = _lab_file(tmp_path / "lab.h5", locations=1)
    _, params = read_measured(lab, spacing=0.004)
    assert (params.n, params.n_y) == (13, 9)                # 48 / 4 + 1, 30 / 4 = 7.5 -> 8, + 1
    res = CliRunner().invoke(cli, ["fit-msm", str(tmp_path / "lab.msm.h5"), "--spacing-mm", "4",
                                   "--workers", "1"])
    assert res.exit_code == 2 and len(res.output.splitlines()) == 1, res.output
    assert "carries the grid it was made on" in res.output


# -- the commands ------------------------------------------------------------------------------

SMALL = ["--locations", "2", "--directions", "2", "--steps", "2", "--fmax", "2", "--workers",
         "1", "--no-rrd"]


def _invoke(*args: str):
    return CliRunner().invoke(cli, [*args], catch_exceptions=False)


def test_simulate_size_makes_the_rectangle(tmp_path):
    out = tmp_path / "rect.h5"
    result = _invoke("-q", "simulate", "--out", str(out), "--size", "48x30", *SMALL[:-1])
    assert result.exit_code == 0, result.output
    with h5py.File(out, "r") as f:
        points, step = f["states/points"][()], f["states/step"][()]
        params = MSMParams(**json.loads(f.attrs["msm_params"]))
        np.testing.assert_allclose(f.attrs["footprint_m"], [0.048, 0.03])
        nodes = f["states/mass"][()]
    assert params == replace(GRID, k_between=100.0, k_fixed=21.0)
    assert points.shape == (2 * 2 * 3, 160, 3)
    np.testing.assert_allclose(points[step == 0] - MSM(params).rest, 0, atol=1e-8)
    assert nodes.max() < 160
    assert out.with_suffix(".rrd").exists()


def test_simulate_layout_takes_the_lab_footprint_markers_and_names(tmp_path):
    lab = _lab_file(tmp_path / "lab.h5", locations=1)
    out = tmp_path / "msm.h5"
    result = _invoke("-q", "simulate", "--out", str(out), "--layout", str(lab), *SMALL)
    assert result.exit_code == 0, result.output
    with h5py.File(out, "r") as f:
        assert json.loads(f.attrs["point_names"]) == [*NAMES, "tip"]
        np.testing.assert_allclose(f.attrs["footprint_m"], [0.048, 0.03])
        assert f["states/points"].shape[1] == len(SCATTERED) + 1
        grid = json.loads(f.attrs["msm_params"])
    assert (grid["n"], grid["n_y"], grid["size"], grid["size_y"]) == (16, 10, 0.048, 0.03)


def test_simulate_params_bring_their_grid_and_refuse_another(tmp_path):
    lab = _lab_file(tmp_path / "lab.h5", locations=2)
    fit = tmp_path / "fit.json"
    result = _invoke("-q", "fit-msm", str(lab), "--out", str(fit), "--no-rrd", "--workers",
                     "1", "--max-sequences", "1")
    assert result.exit_code == 0, result.output
    assert "on 48 x 30 mm of 16 x 10 masses" in result.output
    doc = json.loads(fit.read_text())
    assert (doc["msm_params"]["n"], doc["msm_params"]["n_y"]) == (16, 10)
    out = tmp_path / "msm.h5"
    assert _invoke("-q", "simulate", "--out", str(out), "--params", str(fit),
                   *SMALL).exit_code == 0                    # no size asked: the fit's grid
    with h5py.File(out, "r") as f:
        np.testing.assert_allclose(f.attrs["footprint_m"], [0.048, 0.03])
    assert _invoke("-q", "simulate", "--out", str(out), "--params", str(fit), "--layout",
                   str(lab), "--size", "48x30", *SMALL).exit_code == 0
    for args in (["--size", "100x100"], ["--spacing-mm", "5"]):
        res = CliRunner().invoke(cli, ["simulate", "--out", str(tmp_path / "x.h5"), "--params",
                                       str(fit), *args, *SMALL])
        assert res.exit_code == 2 and len(res.output.splitlines()) == 1, res.output
        assert res.output.startswith(f"error: {fit}:") and "fitted on 48 x 30 mm" in res.output
        assert not (tmp_path / "x.h5").exists()


def test_an_old_square_params_record_still_reads(tmp_path):
    """A phantom.msm_params 1.0 record names n and size alone: the square."""
    old = tmp_path / "old.json"
    old.write_text(json.dumps({"schema": "phantom.msm_params", "schema_version": "1.0",
                               "k_between": 90.0, "k_fixed": 25.0, "mean_distance_m": 1e-4,
                               "msm_params": {"n": 32, "size": 0.1, "k_between": 90.0,
                                              "k_fixed": 25.0}, "provenance": {}}))
    out = tmp_path / "msm.h5"
    assert _invoke("-q", "simulate", "--out", str(out), "--params", str(old), "--size",
                   "100x100", *SMALL).exit_code == 0
    with h5py.File(out, "r") as f:
        assert json.loads(f.attrs["msm_params"])["k_fixed"] == 25.0
    res = CliRunner().invoke(cli, ["simulate", "--out", str(out), "--params", str(old),
                                   "--size", "150x80", *SMALL])
    assert res.exit_code == 2 and "fitted on 100 x 100 mm of 32 x 32 masses" in res.output


def test_a_marker_outside_the_surface_is_one_line(tmp_path):
    lab = _lab_file(tmp_path / "lab.h5", locations=1)
    out = tmp_path / "msm.h5"
    res = CliRunner().invoke(cli, ["simulate", "--out", str(out), "--layout", str(lab),
                                   "--size", "40x30", *SMALL])
    assert res.exit_code == 2 and len(res.output.splitlines()) == 1, res.output
    assert "marker M02 rests at (43.0, 8.0) mm, outside the MSM's 40 x 30 mm" in res.output
    assert not out.exists()


def test_fit_msm_refuses_a_marker_outside_the_surface_as_simulate_does(tmp_path):
    """A footprint smaller than the markers' spread: fit-msm would pin the outer markers to
    the grid's edge and fit them there; it refuses, naming the file."""
    lab = _lab_file(tmp_path / "lab.h5", locations=1)
    with h5py.File(lab, "a") as f:
        f.attrs["footprint_m"] = np.array([0.04, 0.03])
    res = CliRunner().invoke(cli, ["fit-msm", str(lab), "--out", str(tmp_path / "p.json")])
    assert res.exit_code == 2 and len(res.output.splitlines()) == 1, res.output
    assert f"{lab}: marker" in res.output and "outside the MSM's 40 x 30 mm" in res.output
    assert not (tmp_path / "p.json").exists()


def test_a_grid_beyond_the_solver_is_one_line_and_a_spaced_fit_keeps_its_grid(tmp_path):
    """--spacing-mm 0.01 would ask for 10001 x 10001 masses: refused before any work. A fit
    made at 5 mm spacing on the lab's footprint simulates at its own grid with --layout."""
    res = CliRunner().invoke(cli, ["simulate", "--out", str(tmp_path / "x.h5"),
                                   "--spacing-mm", "0.01", *SMALL])
    assert res.exit_code == 2 and "10001 x 10001 masses" in res.output, res.output
    lab = _lab_file(tmp_path / "lab.h5", locations=1)
    fit = tmp_path / "fit.json"
    assert _invoke("-q", "fit-msm", str(lab), "--out", str(fit), "--spacing-mm", "5",
                   "--max-sequences", "1").exit_code == 0
    out = tmp_path / "msm.h5"
    assert _invoke("-q", "simulate", "--out", str(out), "--params", str(fit), "--layout",
                   str(lab), *SMALL).exit_code == 0
    with h5py.File(out, "r") as f:
        grid = json.loads(f.attrs["msm_params"])
    rec = json.loads(fit.read_text())["msm_params"]
    assert (grid["n"], grid["n_y"]) == (rec["n"], rec["n_y"]) and rec["n"] < 32

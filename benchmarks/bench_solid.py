"""The solid model of the phantom: how close it fits a lab, how fast, and how fine its mesh must be.

    python benchmarks/bench_solid.py --states STATES.h5 [--session SESSION_DIR] [--msm]
        [--splits S.json --fold K] [--lump X,Y,R] [--convergence] [--repeats 3]
    python benchmarks/bench_solid.py --states STATES.h5 --hyperelastic SOLID.json [--presses 4]

Prints, beside the host's figure (``core.host_speed``):

1. ``fit-solid`` on the presses given (a fold's training presses with ``--splits``), with the
   interior the session names (its labels as given, or ``"fit"``): each distance (the markers,
   the tip, every point) beside a still surface's; with ``--msm`` the peer, ``fit-msm`` on the
   same presses (every one of them) in the same run: its distance (every point) and time, and
   the ratios solid / MSM;
2. ``simulate --solid`` of 16 places x 3 directions at the lab's markers: its time, and the fit
   and it together in host figures (issue 58's target: <= 30);
3. with ``--convergence``: each marker's displacement under unit loads at three places, on
   markers (the centre, two off-centre) and between them (where a lab presses), on the mesh
   ladder 5 mm / 8 layers -> 3.33 / 12 -> 2.5 / 16 (1.5x the elements along each axis a step),
   the change from one step to the next (every marker, the markers beyond 15 mm of the press,
   the tip), with a 10 mm contact patch and with the fits' 4 mm;
   and the Hertz check's force against Hertz's at 0.9 and 1.2 mm on three meshes.
4. with ``--hyperelastic SOLID.json`` (fit-solid's, on these states): the trade between the
   candidates on ``--presses`` presses of the states (each at another place): the linear
   solid as fitted (its stiffening law), linear elasticity alone (the modulus refitted to
   these presses) and the neo-Hookean solid (``sim/solid/neo_hookean.py``; its modulus
   refitted to these presses: one Newton path a press, its loads scaled, since a neo-Hookean
   field under load F at modulus E is the field under F E0 / E at E0): each one's mean
   distance (every point, mm), seconds a press, Newton steps.

Times are medians of ``--repeats`` runs, each in a fresh process state (the model rebuilt).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np  # noqa: E402

LADDER = ((5.0, 8), (10 / 3, 12), (2.5, 16))       # mm across, layers through
LADDER_RADII = (0.010, 0.004)    # m: a patch every mesh resolves; the fits' (3.8-4.0 mm)


def _timed(fn, repeats: int):  # noqa: ANN001, ANN202
    out, times = None, []
    for _ in range(repeats):
        started = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - started)
    return out, statistics.median(times)


def fit_and_simulate(a: argparse.Namespace, host: float) -> None:
    from sim.msm.fit_msm_params import FitMsmInputs, FitMsmParams
    from sim.msm.fit_msm_stage import run_fit_msm
    from sim.msm.simulate_params import SimulateInputs, SimulateParams
    from sim.msm.simulate_stage import run_simulate
    from sim.solid.fit_solid_params import FitSolidInputs, FitSolidParams
    from sim.solid.fit_solid_stage import run_fit_solid

    with tempfile.TemporaryDirectory() as tmp:
        solid_json = Path(tmp) / "solid.json"
        inputs = FitSolidInputs(a.states, a.splits, a.session)
        params = FitSolidParams(fold=a.fold)
        outcome, fit_s = _timed(lambda: run_fit_solid(inputs, solid_json, params), a.repeats)
        fit = outcome.fit
        print(f"fit-solid: markers {fit.marker_mm:.3f} mm, tip {fit.tip_mm:.3f}, every point "
              f"{fit.all_mm:.3f}; still surface (markers) {fit.still_mm:.3f}; ratios "
              f"{[round(r, 3) for r in fit.material.ratios]} (sd {outcome.fit.sd}); "
              f"{fit_s:.1f} s ({fit_s / host:.1f} x host), {fit.factorisations} factorisations")
        if a.lump:
            over_away(solid_json, a.lump)
        sim_params = SimulateParams(locations=16, directions=3, max_angle_deg=20.0)
        sim_inputs = SimulateInputs(layout=a.states, solid=solid_json)
        _, sim_s = _timed(lambda: run_simulate(sim_inputs, Path(tmp) / "s.h5", sim_params),
                          a.repeats)
        print(f"simulate --solid 16 x 3: {sim_s:.1f} s; fit + simulate {fit_s + sim_s:.1f} s "
              f"= {(fit_s + sim_s) / host:.1f} x the host's figure (target <= 30)")
        if a.msm:
            msm_params = FitMsmParams(fold=a.fold, max_sequences=10_000, workers=2)
            msm, msm_s = _timed(lambda: run_fit_msm(FitMsmInputs(a.states, a.splits), None,
                                                    msm_params), a.repeats)
            d = msm.fit.mean_distance_m * 1e3
            print(f"peer fit-msm (every press, 2 workers): every point {d:.3f} mm in "
                  f"{msm_s:.1f} s; solid / MSM distance {fit.all_mm / d:.2f}, time "
                  f"{fit_s / msm_s:.2f}")


def over_away(solid_json: Path, lump: str) -> None:
    """The fit's mean distance (every point) of the presses over the lump (their place within
    its radius + eval's reach) and away from it, and their ratio (issue 58: <= 1.3)."""
    import json

    from train.evaluation.lump import parse_lump

    where = parse_lump(lump)
    rows = json.loads(solid_json.read_text())["distances_mm"]["per_press"]
    xy = np.array([r["place_mm"] for r in rows]) * 1e-3
    d = np.array([r["all_points"] for r in rows])
    over = where.over(xy)
    if over.any() and (~over).any():
        print(f"over the lump ({over.sum()} presses) {d[over].mean():.3f} mm, away "
              f"({(~over).sum()}) {d[~over].mean():.3f} mm: {d[over].mean() / d[~over].mean():.2f}"
              " x")


def convergence() -> None:
    from sim.solid.block_mesh import BlockGeometry
    from sim.solid.solid_model import Attachments, SolidModel

    top = -0.0015
    grid = 0.010 + 0.020 * np.arange(5)
    markers = np.array([[x, y, 0.0] for y in grid for x in grid])
    at = Attachments.riding(markers, top)
    cases = {"on markers": np.array([[0.05, 0.05, top], [0.03, 0.07, top], [0.07, 0.03, top]]),
             "between markers": np.array([[0.04, 0.04, top], [0.02, 0.06, top],
                                          [0.06, 0.02, top]])}       # where a lab presses
    found: dict = {(c, r): [] for c in cases for r in LADDER_RADII}
    for spacing, layers in LADDER:
        started = time.perf_counter()
        model = SolidModel(BlockGeometry((0.1, 0.1), 0.032, top), spacing * 1e-3, layers)
        solver, probes = model.factorise(np.ones(model.elasticity.n_elements), 0.3), \
            model.probes(at)
        for (case, radius), out in found.items():
            resp = model.respond(solver, cases[case], radius, probes)
            out.append((np.array([r.points for r in resp]), np.array([r.tip for r in resp])))
        print(f"mesh {spacing:.2f} mm / {layers} layers: {model.elasticity.basis.N} unknowns, "
              f"{time.perf_counter() - started:.1f} s")
    for (case, radius), out in found.items():
        far = np.linalg.norm(cases[case][:, None, :2] - markers[None, :, :2], axis=-1) > 0.015
        for (a, ta), (b, tb), (lo, hi) in zip(out, out[1:], zip(LADDER, LADDER[1:],
                                                               strict=False), strict=False):
            change = np.linalg.norm(a - b, axis=-1)                  # (places, 3 loads, P)
            size = np.linalg.norm(b, axis=-1)
            mask = np.broadcast_to(far[:, None, :], change.shape)
            print(f"pressed {case}, patch {radius * 1e3:.0f} mm, {lo[0]:.2f} -> {hi[0]:.2f} mm: "
                  f"markers {change.sum() / size.sum():.1%}, beyond 15 mm "
                  f"{change[mask].sum() / size[mask].sum():.1%}, tip "
                  f"{np.linalg.norm(ta - tb) / np.linalg.norm(tb):.1%}")
    hertz()


def hertz() -> None:
    from skfem import MeshHex

    from sim.solid.block_mesh import graded_axis
    from sim.solid.elasticity import Elasticity, Material
    from sim.solid.sphere_contact import hertz_force, sphere_forces

    depths = np.array([0.9e-3, 1.2e-3])
    for fine in (0.5e-3, 0.4e-3, 0.3e-3):
        axis = graded_axis(0.024, fine, 4.5e-3, 1.5)
        mesh = MeshHex.init_tensor(axis, axis, -axis[::-1])
        el = Elasticity(mesh, symmetry=True)
        solver = el.factorise(Material(np.full(el.n_elements, 1e4), 0.3))
        forces = sphere_forces(el, solver, 0.010, depths, reach=4.5e-3)
        ratio = [f / hertz_force(1e4, 0.3, 0.010, d) for f, d in zip(forces, depths, strict=True)]
        print(f"Hertz, {fine * 1e3:.1f} mm over the contact: force / Hertz at 0.9 and 1.2 mm "
              f"{ratio[0]:.3f}, {ratio[1]:.3f}")


HYPER_GRID = 24            # loads along a press's Newton path
HYPER_RANGE = (1.0, 20.0)  # the refitted modulus, in the linear fit's (neo-Hookean softens)


def hyperelastic(states: Path, solid_json: Path, count: int, host: float) -> None:
    """The candidates' distance and seconds on ``count`` presses (each at another place)."""
    from sim.solid.elasticity import Material
    from sim.solid.measured_presses import read_presses
    from sim.solid.neo_hookean import NeoHookean
    from sim.solid.solid_file import read_solid
    from sim.solid.solid_model import predict

    solid, data = read_solid(solid_json), read_presses(states)
    m, model = solid.material, solid.model
    _, first = np.unique([p.location for p in data.presses], return_index=True)
    presses = [data.presses[i] for i in sorted(first)[:count]]
    at = data.attachments()
    probes = model.probes(at)
    started = time.perf_counter()
    solver = solid.factorise()
    resps = model.respond(solver, np.array([p.rest[-1] for p in presses]), m.contact_radius,
                          probes)
    lin_s = (time.perf_counter() - started) / len(presses)
    loads = [np.vstack([np.zeros(3), p.loads(r.tip)]) for p, r in zip(presses, resps,
                                                                         strict=True)]
    neo = NeoHookean(model.elasticity, Material(solid.element_ratios * m.modulus, m.poisson))
    paths, steps, neo_s = [], [], []
    for press, resp, load in zip(presses, resps, loads, strict=True):
        tic = time.perf_counter()
        paths.append(_newton_path(neo, model, resp.place, load, m.contact_radius, probes, at,
                                  steps))
        neo_s.append(time.perf_counter() - tic)
        print(f"  neo-Hookean press {press.sequence}: {neo_s[-1]:.0f} s, "
              f"{len(paths[-1][0]) - 1} of {HYPER_GRID} loads solved", flush=True)

    def linear(scale: float, stiffening: float) -> float:
        return _distance(presses, [predict(r, ld, m.modulus * scale, stiffening, m.reach, at)
                                   for r, ld in zip(resps, loads, strict=True)])

    def hyper(scale: float) -> float:
        found = [_along(path, ld, scale) for path, ld in zip(paths, loads, strict=True)]
        return np.inf if any(f is None for f in found) else _distance(presses, found)

    scales = np.geomspace(*HYPER_RANGE, 60)
    pure = min(scales, key=lambda k: linear(k, 0.0))
    best = min(scales, key=hyper)
    print(f"| candidate | distance, every point (mm) | modulus (Pa) | seconds a press "
          f"| x host a press |\n|---|---|---|---|---|\n"
          f"| linear, its stiffening law (as fitted) | {linear(1.0, m.stiffening):.3f} | "
          f"{m.modulus:.0f} | {lin_s:.2f} | {lin_s / host:.2f} |\n"
          f"| linear elasticity alone | {linear(pure, 0.0):.3f} | {m.modulus * pure:.0f} | "
          f"{lin_s:.2f} | {lin_s / host:.2f} |\n"
          f"| neo-Hookean, Newton ({np.median(steps):.0f} steps a load, median) | "
          f"{hyper(best):.3f} | {m.modulus * best:.0f} | {np.median(neo_s):.0f} | "
          f"{np.median(neo_s) / host:.0f} |")


def _newton_path(neo, model, place, load, radius, probes, at, steps):  # noqa: ANN001, ANN202
    """A press's points and tip along HYPER_GRID loads up to its deepest (scaled to the
    lowest modulus of HYPER_RANGE), as far as Newton reaches: (fractions, points, tip, the
    deepest load's size)."""
    deepest = load[np.argmax(np.linalg.norm(load, axis=1))] / HYPER_RANGE[0]
    fractions = np.linspace(0.0, 1.0, HYPER_GRID + 1)
    unit = model.unit_loads(place, radius)[0] @ deepest                  # (N,)
    solved = neo.press(fractions[1:, None] * unit[None], partial=True)
    steps.extend(solved.steps)
    fields = np.vstack([np.zeros((1, len(unit))), solved.fields])
    pts, tip = model.observe(fields, place, radius, probes, at)
    return fractions[:len(fields)], pts, tip, float(np.linalg.norm(deepest))


def _along(path, load, scale):  # noqa: ANN001, ANN202
    """A press's points and tip at its loads (T, 3) for the modulus ``scale`` x the fit's,
    interpolated along its Newton path; None where a load lies past the path's end."""
    fractions, pts, tip, deepest = path
    f = np.linalg.norm(load, axis=1) / (scale * deepest)
    if f.max() > fractions[-1] + 1e-12:
        return None
    i = np.clip(np.searchsorted(fractions, f) - 1, 0, len(fractions) - 2)
    w = ((f - fractions[i]) / (fractions[i + 1] - fractions[i]))[:, None]
    return (pts[i] * (1 - w[..., None]) + pts[i + 1] * w[..., None],
            tip[i] * (1 - w) + tip[i + 1] * w)


def _distance(presses, predicted) -> float:  # noqa: ANN001
    """Mean distance (mm) of every point (the markers and the tip) over the presses' loaded
    states, each press's prediction moved onto its own rest."""
    found = []
    for press, (pts, tip) in zip(presses, predicted, strict=True):
        moved = np.concatenate([pts, tip[:, None]], axis=1)
        d = np.linalg.norm(press.rest[None] + moved[1:] - moved[:1] - press.states, axis=-1)
        found.append(d[np.isfinite(d)])
    return float(np.concatenate(found).mean() * 1e3)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--states", type=Path)
    ap.add_argument("--session", type=Path)
    ap.add_argument("--splits", type=Path)
    ap.add_argument("--fold", type=int, default=0)
    ap.add_argument("--msm", action="store_true", help="fit-msm beside it (the peer)")
    ap.add_argument("--lump", help="X,Y,R mm: the fit's distance over the lump and away")
    ap.add_argument("--convergence", action="store_true")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--hyperelastic", type=Path, metavar="SOLID.json",
                    help="the candidates' trade on --presses presses of --states")
    ap.add_argument("--presses", type=int, default=4)
    a = ap.parse_args()
    from core.host_speed import host_speed

    host = host_speed()
    print(f"host figure {host:.2f} s")
    if a.states is not None and a.hyperelastic is not None:
        hyperelastic(a.states, a.hyperelastic, a.presses, host)
    elif a.states is not None:
        fit_and_simulate(a, host)
    if a.convergence:
        convergence()


if __name__ == "__main__":
    main()

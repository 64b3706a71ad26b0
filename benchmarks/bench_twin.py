"""How fast is the phantom twin, and is its fast static solver right?

Times, as medians over repeats:

* one press of the volumetric phantom (17 force levels, 20 degrees off the normal): the twin's
  solver (nonlinear conjugate gradients preconditioned with the one factorisation of the rest
  stiffness, cubic extrapolation between levels) against the peer, Newton's method with a
  fresh sparse factorisation of the tangent stiffness at every iteration; both to the same
  force tolerance, and the largest difference of their equilibria. The twin's rest
  factorisation is made once per session and shared by its presses: it is timed on its own
  and the ratio is given with it amortised over a default session's presses and with it
  charged in full to the one press;
* a default session (5 locations x 4 repeats, ``run_synth`` without a recording),
  split into simulation and writing, against the peer that reads it back, ``pipeline ingest``.

    python benchmarks/bench_twin.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ingest.ingest_stage import run_ingest
from sim.twin.phantom import Phantom
from sim.twin.synth_params import SynthParams
from sim.twin.synth_stage import write_twin
from sim.twin.twin import simulate_twin
from sim.twin.twin_scene import TwinParams

LEVELS = np.concatenate([[0.25], np.arange(0.5, 7.01, 0.5), [7.2, 7.3]])
TILT = np.radians(20.0)
DIRECTION = np.array([np.sin(TILT), 0.0, -np.cos(TILT)])
LOCATION = (8, 12)


def newton_path(ph: Phantom) -> np.ndarray:
    """The peer: full Newton steps, a new sparse LU of the tangent at every iteration; refuses
    a level it does not converge at within 50 iterations."""
    unit = np.zeros(ph.n_dof)
    for node, w in ph._patch(LOCATION):
        unit[ph.dof[node]] += w * DIRECTION
    A, AT, c, beta = ph._A, ph._AT, ph._energy, ph.spec.stiffening
    u, out = np.zeros(ph.n_dof), []
    for f in LEVELS:
        for _ in range(50):
            e = A @ u
            g = AT @ (c * e * (1 + beta * e * e)) - f * unit
            if np.abs(g).max() < ph.spec.tol:
                break
            k = (AT @ sp.diags(c * (1 + 3 * beta * e * e)) @ A).tocsc()
            u = u - spla.splu(k, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                              options={"SymmetricMode": True}).solve(g)
        else:
            raise RuntimeError(f"Newton peer did not converge at {f:g} N")
        out.append(ph.observe(u, LOCATION)[0])
    return np.array(out)


def median_time(fn, repeats: int) -> tuple[float, object]:  # noqa: ANN001
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    ph = Phantom()
    factor_s, _ = median_time(lambda: _refactor(ph), args.repeats)
    fast, path = median_time(lambda: ph.load_path(LOCATION, DIRECTION, LEVELS), args.repeats)
    slow, tips = median_time(lambda: newton_path(ph), args.repeats)
    diff = np.abs(path.tip[1:] - tips).max()
    presses = TwinParams().locations * TwinParams().repeats
    shared = fast + factor_s / presses
    print(f"phantom press ({len(LEVELS)} levels): twin solver {fast * 1e3:.0f} ms + rest "
          f"factorisation {factor_s * 1e3:.0f} ms once per session; Newton + LU per "
          f"iteration {slow * 1e3:.0f} ms (converged at every level); largest tip difference "
          f"{diff * 1e6:.2f} um")
    print(f"  ratio Newton / twin: {slow / shared:.1f}x with the factorisation shared by a "
          f"session's {presses} presses, {slow / (fast + factor_s):.1f}x charging it all to "
          "one press")

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "session"
        sim_s, twin = median_time(lambda: simulate_twin(TwinParams(seed=0)), args.repeats)
        write_s, _ = median_time(lambda: write_twin(twin, folder, SynthParams(seed=0)),
                                 args.repeats)
        read_s, _ = median_time(lambda: run_ingest(folder, Path(tmp) / "s.mcap"),
                                args.repeats)
        frames = len(twin.mocap.time_s)
        print(f"default session ({len(twin.hand.presses)} presses, {frames} frames, "
              f"{frames / twin.params.rate_hz:.0f} s): simulate {sim_s:.1f} s + write "
              f"{write_s:.1f} s = {sim_s + write_s:.1f} s; peer ingest {read_s:.1f} s; "
              f"ratio synth/ingest {(sim_s + write_s) / read_s:.1f}x")


def _refactor(ph: Phantom) -> object:
    """Make the phantom's rest factorisation again (it is cached on first use)."""
    ph.__dict__.pop("_rest_lu", None)
    return ph._rest_lu


if __name__ == "__main__":
    main()

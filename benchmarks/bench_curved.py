"""Sync and extract on curved phantom twins against their truth.

For each shape (``dome:30``, the issue's dome: a cap 30 mm high on the default footprint, and
a half-cylinder lying on its flat face, written here as an OBJ the twin was not designed
around) and each seed: synthesise a session (5 x 5 markers, 8 places x 2 presses), ingest,
sync and extract it, and compare with ``truth.h5``: the registration (each marker's residual
off the registered shape, the frame against the true one), the tip, the depth along the
surface normal where each press touched, and the states (mean distance to the true ones at
the same level, missing levels). Prints one row per run and the median and worst over seeds;
then sync's wall time on the dome of seed 0 against the flat twin of the same seed (its peer:
the rest plane instead of the registration and the shape's depth), median of ``--repeats``
runs of each, interleaved.

Run: ``python benchmarks/bench_curved.py [--seeds 3] [--repeats 3] [--workdir DIR]``.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

from core.progress import set_quiet
from core.protocol import STEP_N, top_level
from extract.extract_params import ExtractParams
from extract.extract_stage import run_extract
from extract.phantom_frame import apply_transform
from ingest.ingest_stage import run_ingest
from sim.twin.synth_params import SynthParams
from sim.twin.synth_stage import run_synth
from sync.sync_accuracy import curved_errors, sync_errors
from sync.sync_params import SyncParams
from sync.sync_stage import run_sync

HALF_CYLINDER = "half_cylinder.obj"


def write_half_cylinder(path: Path, radius_mm: float = 50.0, length_mm: float = 100.0,
                        sections: int = 64) -> Path:
    """A half-cylinder lying on its flat face (axis along x at y = radius, on z = 0) as an OBJ
    in mm: the arc's vertices at both ends, the curved side, the flat bottom and two half-disc
    ends."""
    a = np.linspace(0.0, np.pi, sections + 1)
    arc = np.c_[radius_mm * (1 + np.cos(a)), radius_mm * np.sin(a)]      # (y, z)
    ends = [np.c_[np.full(len(arc), x), arc] for x in (0.0, length_mm)]
    verts = np.r_[ends[0], ends[1]]
    n = len(arc)
    faces = [(i, i + 1, n + i + 1) for i in range(n - 1)] + \
            [(i, n + i + 1, n + i) for i in range(n - 1)]
    faces += [(0, n, 2 * n - 1), (0, 2 * n - 1, n - 1)]                  # the flat bottom
    faces += [(0, i + 1, i) for i in range(1, n - 1)]                    # the end at x = 0
    faces += [(n, n + i, n + i + 1) for i in range(1, n - 1)]            # the end at x = L
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in verts]
    lines += [f"f {i + 1} {j + 1} {k + 1}" for i, j, k in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def run_one(shape: str, seed: int, d: Path) -> dict[str, float]:
    """One curved session through synth, ingest, sync and extract, against its truth."""
    folder = run_synth(None, d / "s", SynthParams(seed=seed, locations=8, repeats=2,
                                                  shape=shape))
    mcap, synced, states = d / "s.mcap", d / "s.h5", d / "states.h5"
    run_ingest(folder, mcap, None, None)
    run_sync(mcap, synced, SyncParams(), None)
    run_extract([synced], states, ExtractParams(), None)
    return {**curved_errors(synced, folder / "truth.h5"),
            "tip_rms_mm": sync_errors(synced, folder / "truth.h5")["tip_rms_mm"],
            **state_errors(states, folder / "truth.h5")}


def state_errors(states: Path, truth: Path) -> dict[str, float]:
    """The states' mean distance (mm) to the true ones at the same level (through the file's
    own frame), and how many levels the presses reached that no state holds, excluded ones
    (saturated, too fast) apart."""
    with h5py.File(states) as s, h5py.File(truth) as t:
        seq, step = s["states/sequence"][()], s["states/step"][()]
        pts, valid = s["states/points"][()], s["states/valid"][()]
        to_phantom = s["sessions/transform"][0]
        t_pts, t_step, t_press = (t["states/points"][()], t["states/step"][()],
                                  t["states/press"][()])
        dist = []
        for i in range(len(seq)):
            j = np.flatnonzero((t_press == seq[i]) & (t_step == step[i]))
            if j.size:
                true = apply_transform(to_phantom, t_pts[j[0]])
                dist.append(np.linalg.norm(pts[i][valid[i]] - true[valid[i]], axis=1).mean())
        excluded = sum(json.loads(s.attrs["excluded"]).values())
        force, pressing = t["force/magnitude"][()], t["mocap/press"][()]
        reached = sum(top_level(force[pressing == k].max(), STEP_N) + 1
                      for k in np.unique(t_press))
    return {"states_mm": float(np.mean(dist)) * 1e3,
            "states_missing": float(reached - len(seq) - excluded)}


def sync_seconds(work: Path, repeats: int) -> None:
    """Sync's wall time on the dome of seed 0 and on the flat twin of seed 0 (the same places
    and presses), median of ``repeats`` interleaved runs, and their ratio."""
    flat = work / "flat_0"
    flat.mkdir(exist_ok=True)
    run_synth(None, flat / "s", SynthParams(seed=0, locations=8, repeats=2))
    run_ingest(flat / "s", flat / "s.mcap", None, None)
    times: dict[str, list[float]] = {"dome": [], "flat": []}
    for _ in range(repeats):
        for name, d in (("dome", work / "dome30_0"), ("flat", flat)):
            start = time.perf_counter()
            run_sync(d / "s.mcap", d / "t.h5", SyncParams(), None)
            times[name].append(time.perf_counter() - start)
    dome, flat_s = (float(np.median(times[k])) for k in ("dome", "flat"))
    print(f"sync, 16 presses: dome {dome:.2f} s, flat {flat_s:.2f} s (median of {repeats}); "
          f"dome / flat {dome / flat_s:.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=3, help="twin seeds 0..N-1 per shape")
    ap.add_argument("--repeats", type=int, default=3, help="timed syncs (the median is quoted)")
    ap.add_argument("--workdir", type=Path, default=None,
                    help="where the sessions go [default: a new temporary folder]")
    args = ap.parse_args()
    set_quiet(True)
    work = args.workdir or Path(tempfile.mkdtemp(prefix="bench_curved_"))
    work.mkdir(parents=True, exist_ok=True)
    cylinder = str(write_half_cylinder(work / HALF_CYLINDER))
    keys = ("residual_max_mm", "frame_mm", "frame_deg", "tip_rms_mm", "depth_rms_mm",
            "depth_max_mm", "states_mm", "states_missing")
    print("shape          seed  " + "  ".join(f"{k:>15s}" for k in keys))
    for shape in ("dome:30", cylinder):
        rows = []
        for seed in range(args.seeds):
            d = work / f"{Path(shape).stem.replace(':', '')}_{seed}"
            d.mkdir(parents=True, exist_ok=True)
            rows.append(run_one(shape, seed, d))
            print(f"{Path(shape).name:14s} {seed:4d}  "
                  + "  ".join(f"{rows[-1][k]:15.3f}" for k in keys), flush=True)
        worst = {k: max(r[k] for r in rows) for k in keys}
        med = {k: float(np.median([r[k] for r in rows])) for k in keys}
        print(f"{'median':19s} " + "  ".join(f"{med[k]:15.3f}" for k in keys))
        print(f"{'worst':19s} " + "  ".join(f"{worst[k]:15.3f}" for k in keys))
    sync_seconds(work, args.repeats)


if __name__ == "__main__":
    main()

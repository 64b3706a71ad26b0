"""Accuracy and speed of `pipeline sync` on default-size phantom-twin sessions.

For each seed: synthesise a session (5 locations x 4 repeats), ingest it, sync it with the
trigger clock and with the data-driven clock, and compare both with the twin's truth; and the
same seed with the force through the mocap's analog board (``--force-via analog``: one shared
clock, nothing to estimate). Prints the median and worst error over seeds against sync's
accuracy targets (:data:`sync.sync_accuracy.TARGETS`), and the ratios against peers measured
in the same run:

* clock: the data-driven estimate against the trigger (error ratio);
* force: our anti-aliased resampler against naive decimation (the logger sample nearest each
  mocap frame, i.e. every other sample), same clock, tare and re-tare;
* tip: the low-passed, robustly fitted tip against a plain per-frame least-squares tip;
* re-tare: on one long session (20 presses of 20 s, about 7 minutes, the sensor's bias
  creeping), the force with the re-tare at every press against the tare at the start only;
* wall time of sync on seed 0 (median over repeats) with and without the rerun recording,
  same session and runs of each kind interleaved; the per-seed timings are reported apart.

Run: ``python benchmarks/bench_sync.py [--seeds 5] [--repeats 3] [--workdir DIR]``.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

from calib.force_tare import apply_calibration, rest_baseline
from core.progress import set_quiet
from ingest.ingest_stage import run_ingest
from ingest.mcap_io import read_raw_mcap
from sim.twin.synth_params import SynthParams
from sim.twin.synth_stage import run_synth
from sync.clock import ClockFit
from sync.sync_accuracy import TARGETS, sync_errors
from sync.sync_params import SyncParams
from sync.sync_stage import run_sync


def naive_force_rms(mcap: Path, synced: Path, truth: Path) -> float:
    """Force-magnitude RMS error when each mocap frame takes the nearest logger sample (the
    synced file's clock, tare and re-tare)."""
    raw = read_raw_mcap(mcap)
    p = SyncParams()
    with h5py.File(synced) as s, h5py.File(truth) as t:
        bias = s["calibration/force_bias"][:]
        cal = s["calibration"].attrs
        clock = ClockFit(cal["clock_offset_s"], cal["clock_drift_ppm"], 0.0, 0.0, 0.0, 0, "")
        noise = json.loads(s.attrs["calibration"])["force"]["noise_force_n"]
        true_force = t["force/magnitude"][:]
        rate = t.attrs["rate_hz"]
        matrix = raw.calibration.matrix if raw.force.kind == "gauge" else None
        t_f = raw.force.time_ns * 1e-9
        wrench = apply_calibration(raw.force.values, bias, matrix)
        contact = max(p.contact_n, 5 * noise)
        wrench -= rest_baseline(t_f, wrench, contact, max(contact, 0.5 * p.detect_n)).at(t_f)
        mag = np.linalg.norm(wrench[:, :3], axis=1)
        err = []
        for g in s["presses"].values():
            t_m = g["time_ns"][:] * 1e-9
            j = np.clip(np.round((clock.to_logger(t_m) - t_f[0]) * raw.force.rate_hz)
                        .astype(int), 0, len(t_f) - 1)
            err.append(mag[j] - true_force[np.round(t_m * rate).astype(int)])
    e = np.concatenate(err)
    return float(np.sqrt(np.mean(e**2)))


def long_session_force(workdir: Path) -> dict[str, tuple[float, float]]:
    """Loaded-force RMS (all presses, last press) of a 7-minute session, re-tared or not."""
    folder = run_synth(None, workdir / "long", SynthParams(seed=0, press_seconds=20.0))
    mcap = workdir / "long.mcap"
    run_ingest(folder, mcap)
    out = {}
    for key, retare in (("on", True), ("off", False)):
        synced = workdir / f"long_{key}.h5"
        run_sync(mcap, synced, SyncParams(retare=retare))
        whole = sync_errors(synced, folder / "truth.h5")["force_rms_loaded_n"]
        with h5py.File(synced) as s, h5py.File(folder / "truth.h5") as t:
            g = s["presses"][sorted(s["presses"])[-1]]
            on, off = g.attrs["onset_index"], g.attrs["release_index"]
            frames = np.round(g["time_ns"][on:off] * 1e-9 * t.attrs["rate_hz"]).astype(int)
            err = g["force_magnitude"][on:off] - t["force/magnitude"][:][frames]
        out[key] = (whole, float(np.sqrt(np.mean(err**2))))
    return out


def run(seeds: int, repeats: int, workdir: Path) -> None:
    set_quiet(True)
    rows: dict[str, list[dict[str, float]]] = {"trigger": [], "data": [], "plain_tip": [],
                                               "analog": []}
    naive, times_seeds, times, times_rrd = [], [], [], []
    for seed in range(seeds):
        folder = run_synth(None, workdir / f"s{seed}", SynthParams(seed=seed))
        mcap = workdir / f"s{seed}.mcap"
        run_ingest(folder, mcap)
        truth = folder / "truth.h5"
        for method in ("trigger", "data"):
            out = workdir / f"s{seed}_{method}.h5"
            start = time.perf_counter()
            run_sync(mcap, out, SyncParams(clock=method))
            if method == "trigger":
                times_seeds.append(time.perf_counter() - start)
            rows[method].append(sync_errors(out, truth))
        naive.append(naive_force_rms(mcap, workdir / f"s{seed}_trigger.h5", truth))
        plain = workdir / f"s{seed}_plain.h5"
        run_sync(mcap, plain, SyncParams(robust_scale_m=0.0, tip_cutoff_hz=0.0))
        rows["plain_tip"].append(sync_errors(plain, truth))
        analog = run_synth(None, workdir / f"a{seed}", SynthParams(seed=seed, force_via="analog"))
        run_ingest(analog, workdir / f"a{seed}.mcap")
        run_sync(workdir / f"a{seed}.mcap", workdir / f"a{seed}.h5")
        rows["analog"].append(sync_errors(workdir / f"a{seed}.h5", analog / "truth.h5"))
        print(f"seed {seed}: done", flush=True)
    retare = long_session_force(workdir)
    mcap = workdir / "s0.mcap"
    for _ in range(repeats):
        start = time.perf_counter()
        run_sync(mcap, workdir / "t.h5")
        times.append(time.perf_counter() - start)
        start = time.perf_counter()
        run_sync(mcap, workdir / "t.h5", None, workdir / "t.rrd")
        times_rrd.append(time.perf_counter() - start)
    _report(rows, naive, retare, times_seeds, times, times_rrd, seeds)


def _report(rows: dict[str, list[dict[str, float]]], naive: list[float],
            retare: dict[str, tuple[float, float]], times_seeds: list[float],
            times: list[float], times_rrd: list[float], seeds: int) -> None:
    def stat(method: str, key: str) -> tuple[float, float]:
        v = np.array([r[key] for r in rows[method]])
        return float(np.median(v)), float(np.max(v))

    print(f"\nsync accuracy against the twin's truth, {seeds} default-size sessions "
          "(5 locations x 4 repeats)")
    print(f"{'error':<18}{'target':>8}{'trigger med':>13}{'max':>9}{'data med':>10}{'max':>9}"
          f"{'pass':>6}{'analog med':>12}{'max':>9}")
    for key, target in TARGETS.items():
        tm, tx = stat("trigger", key)
        dm, dx = stat("data", key)
        am, ax = stat("analog", key)
        print(f"{key:<18}{target:>8.3g}{tm:>13.4f}{tx:>9.4f}{dm:>10.4f}{dx:>9.4f}"
              f"{'yes' if tx <= target else 'NO':>6}{am:>12.4f}{ax:>9.4f}")
    loaded = stat("trigger", "force_rms_loaded_n")
    coverage = [r["tip_coverage"] for r in rows["trigger"]]
    print(f"force RMS from onset to release only [N]: median {loaded[0]:.4f}, max "
          f"{loaded[1]:.4f}; tip coverage: median {np.median(coverage):.4f}, lowest "
          f"{min(coverage):.4f}")
    count = {k: sum(r[k] for r in rows["trigger"]) for k in
             ("presses", "presses_missed", "presses_extra", "presses_merged", "locations_mixed")}
    print(f"presses found {count['presses']:.0f}, missed {count['presses_missed']:.0f}, extra "
          f"{count['presses_extra']:.0f}, merged {count['presses_merged']:.0f}, location ids "
          f"wrong {count['locations_mixed']:.0f}")
    print("\npeers (same sessions, median over seeds; ratio = peer error / ours)")
    for key, label in (("clock_offset_ms", "clock offset [ms]"),
                       ("clock_drift_ppm", "clock drift [ppm]")):
        tm, dm = stat("trigger", key)[0], stat("data", key)[0]
        print(f"  {label:<34} trigger {tm:.4f}  data-driven {dm:.4f}  ratio "
              f"{dm / max(tm, 1e-12):.2f}")
    ours_f = stat("trigger", "force_rms_n")[0]
    print(f"  {'force magnitude RMS [N]':<34} anti-aliased {ours_f:.4f}  naive decimation "
          f"{np.median(naive):.4f}  ratio {np.median(naive) / ours_f:.2f}")
    ours_t, plain_t = stat("trigger", "tip_rms_mm")[0], stat("plain_tip", "tip_rms_mm")[0]
    print(f"  {'tip RMS [mm]':<34} robust+low-pass {ours_t:.4f}  plain LS {plain_t:.4f}  "
          f"ratio {plain_t / ours_t:.2f}")
    on, off = retare["on"], retare["off"]
    print(f"  {'loaded force RMS, 7-min session [N]':<34} re-tared {on[0]:.4f} (last press "
          f"{on[1]:.4f})  start tare only {off[0]:.4f} (last press {off[1]:.4f})  ratio "
          f"{off[0] / on[0]:.2f}")
    print(f"\nsync wall time, seed 0, median of {len(times)} (s): {np.median(times):.2f} without "
          f"recording, {np.median(times_rrd):.2f} with; ratio "
          f"{np.median(times_rrd) / np.median(times):.2f}")
    print(f"sync wall time per seed, trigger clock, no recording (s): "
          f"{', '.join(f'{x:.2f}' for x in times_seeds)}")


def trigger_matching_time(repeats: int) -> None:
    """match_trigger on a half-hour session (1,200 pulses, every 97th edge missed): the
    vectorised count of 1.4 million (edge, event) proposals, median of ``repeats``."""
    from sync.clock import match_trigger

    rng = np.random.default_rng(5)
    events = np.cumsum(rng.uniform(0.7, 2.3, 1200))
    edges = 0.8 + (1 + 30e-6) * events + rng.uniform(-5e-4, 5e-4, len(events))
    edges = np.delete(edges, np.arange(0, 1200, 97))
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        match_trigger(edges, events, source="bench")
        times.append(time.perf_counter() - start)
    print(f"trigger matching, 1,200 pulses: median {np.median(times):.3f} s over {repeats}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--workdir", type=Path, default=None)
    a = ap.parse_args()
    trigger_matching_time(a.repeats)
    if a.workdir is not None:
        a.workdir.mkdir(parents=True, exist_ok=True)
        run(a.seeds, a.repeats, a.workdir)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            run(a.seeds, a.repeats, Path(tmp))


if __name__ == "__main__":
    main()

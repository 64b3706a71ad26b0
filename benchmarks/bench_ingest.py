"""How fast and how lean is `pipeline ingest` on a 10-minute lab session?

Generates (seeded, in a temporary folder) a QTM 3D export of 29 markers at 500 Hz for 10
minutes (300,000 frames, real TSV header keys, a Frame/Time column line, occlusion gaps), a
1 kHz six-gauge force CSV of the same length, an ATI .cal and session.toml. Then times, as the
median over repeats:

* ``run_ingest`` without a recording, and with one;
* the peer: a bare ``pandas.read_csv`` of the same TSV data block into a float64 array;

and prints the ratio (target: ingest within 1.5x of the bare parse). Peak memory of each, in a
fresh subprocess (``ru_maxrss`` growth over the imports), is compared with the size of the
parsed arrays (target: within 3x). ``--profile`` prints where ingest spends its time.

``--mat`` also times the same session with the mocap as a compressed QTM MAT v7 export against
its peer, a bare ``scipy.io.loadmat`` of that file (the MAT must be inflated once, not once per
format check).

    python benchmarks/bench_ingest.py [--minutes 10] [--repeats 3] [--profile] [--mat]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

MARKERS = [f"P{r}{c}" for r in range(5) for c in range(5)] + ["Ind 1", "Ind 2", "Ind 3", "Ind 4"]
RATE, FORCE_RATE = 500, 1000
HEADER_LINES = 12           # 9 header keys, MARKER_NAMES, TRAJECTORY_TYPES, column line


def write_session(folder: Path, minutes: float, seed: int = 0) -> dict[str, float]:
    """Write the session files; return the sizes (bytes) of the arrays a reader must build."""
    rng = np.random.default_rng(seed)
    frames, m = int(minutes * 60 * RATE), len(MARKERS)
    base = rng.uniform(-50, 150, (m, 3))
    pos = np.round(base + 0.5 * np.sin(np.arange(frames)[:, None, None] / 700.0 + base / 9)
                   + rng.normal(0, 0.05, (frames, m, 3)), 3)
    for _ in range(int(minutes * 20)):                       # ~20 occlusions per minute
        f0, k, mk = rng.integers(0, frames - 500), rng.integers(1, 400), rng.integers(0, m)
        pos[f0:f0 + k, mk] = np.nan
    gaps = int(np.isnan(pos).any(axis=2).sum())
    _write_tsv(folder / "trial_3d.tsv", pos, minutes)
    n_force = int(minutes * 60 * FORCE_RATE)
    volts = np.round(rng.normal(0, 0.3, (n_force, 6)), 6)
    df = pd.DataFrame(volts, columns=[f"G{i}" for i in range(6)])
    df.insert(0, "time", np.arange(n_force) / FORCE_RATE)
    df.to_csv(folder / "force.csv", index=False, float_format="%.6f")
    (folder / "FT0001.cal").write_text(_cal_xml(rng))
    names = ", ".join(f'"{n}"' for n in MARKERS[:25])
    (folder / "session.toml").write_text(
        f'schema = "phantom.session"\nschema_version = "1.0"\nname = "bench"\n\n[mocap]\n'
        f'file = "trial_3d.tsv"\nphantom_markers = [{names}]\n'
        f'indenter_markers = ["Ind 1", "Ind 2", "Ind 3", "Ind 4"]\n\n[force]\n'
        f'file = "force.csv"\ntime_column = "time"\ntime_unit = "s"\nkind = "gauge"\n'
        f'channels = ["G0", "G1", "G2", "G3", "G4", "G5"]\nunits = "V"\n'
        f'calibration = "FT0001.cal"\n')
    return {"positions": pos.nbytes, "mocap_time": frames * 8.0, "force": volts.nbytes,
            "force_time": n_force * 8.0, "gap_samples": gaps}


def _write_tsv(path: Path, pos: np.ndarray, minutes: float) -> None:
    frames, m = pos.shape[:2]
    head = [f"NO_OF_FRAMES\t{frames}", "NO_OF_CAMERAS\t12", f"NO_OF_MARKERS\t{m}",
            f"FREQUENCY\t{RATE}", "NO_OF_ANALOG\t0", "ANALOG_FREQUENCY\t0", "DESCRIPTION\t--",
            "TIME_STAMP\t2026-11-21, 09:30:00.000\t5021.25", "DATA_INCLUDED\t3D",
            "MARKER_NAMES\t" + "\t".join(MARKERS),
            "TRAJECTORY_TYPES\t" + "\t".join(["Measured"] * m),
            "Frame\tTime\t" + "\t".join(f"{n} {a}" for n in MARKERS for a in "XYZ") + "\t"]
    assert len(head) == HEADER_LINES
    df = pd.DataFrame(pos.reshape(frames, -1))
    df.insert(0, "time", [f"{t:.5f}" for t in np.arange(frames) / RATE])
    df.insert(0, "frame", np.arange(1, frames + 1))
    with open(path, "w", newline="") as f:
        f.write("\r\n".join(head) + "\r\n")
        df.to_csv(f, sep="\t", header=False, index=False, float_format="%.3f",
                  lineterminator="\t\r\n")


def _cal_xml(rng: np.random.Generator) -> str:
    rows = "".join(
        f'    <UserAxis Name="{a}" values="{" ".join(f"{v:.5f}" for v in rng.normal(0, 5, 6))}" '
        f'max="{mx}"/>\n' for a, mx in zip(("Fx", "Fy", "Fz", "Tx", "Ty", "Tz"),
                                            (12, 12, 17, 120, 120, 120), strict=True))
    return ('<?xml version="1.0" encoding="utf-8"?>\n<FTSensor Serial="FT0001" '
            'BodyStyle="Nano17" Family="DAQ" NumGages="6" CalFileVersion="1.1">\n  '
            '<Calibration PartNumber="SI-12-0.12" CalDate="1/1/2026" ForceUnits="N" '
            'TorqueUnits="N-mm" DistUnits="mm">\n' + rows + "  </Calibration>\n</FTSensor>\n")


def write_mat_session(folder: Path, mat_folder: Path) -> Path:
    """The session of ``folder`` with its mocap as a QTM MAT v7 export; returns the MAT file."""
    import shutil

    from ingest.detect import read_mocap
    from ingest.qtm_mat import write_qtm_mat

    mat_folder.mkdir()
    mat = mat_folder / "trial_3d.mat"
    write_qtm_mat(mat, read_mocap(folder / "trial_3d.tsv"), version="7")
    for name in ("force.csv", "FT0001.cal"):
        shutil.copy(folder / name, mat_folder / name)
    toml = (folder / "session.toml").read_text().replace('"trial_3d.tsv"', '"trial_3d.mat"')
    (mat_folder / "session.toml").write_text(toml)
    return mat


def bare_loadmat(mat: Path) -> dict:
    """The peer of a MAT ingest: scipy's loadmat of the whole file."""
    import scipy.io

    return scipy.io.loadmat(mat)


def bare_parse(tsv: Path) -> np.ndarray:
    """The peer: pandas' C parser on the TSV data block, to one float64 array."""
    return pd.read_csv(tsv, sep="\t", skiprows=HEADER_LINES, header=None).to_numpy(np.float64)


def ingest(folder: Path, out: Path, rrd: Path | None) -> None:
    from core.progress import set_quiet
    from ingest.ingest_stage import run_ingest

    set_quiet(True)
    run_ingest(folder, out, None, rrd)


def timed(fn, fresh: tuple[Path, ...] = ()) -> float:  # noqa: ANN001 - any callable
    """Wall time of ``fn()``; the ``fresh`` outputs are deleted (untimed) first."""
    for p in fresh:
        p.unlink(missing_ok=True)
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


_PEAK = """
import sys
sys.path.insert(0, {root!r})
import numpy, pandas, rerun, mcap, h5py, zstandard
import benchmarks.bench_ingest as b
import ingest.ingest_stage, ingest.ingest_view, ingest.detect, ingest.force_log
def hwm():
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024
base = hwm()
{call}
print(hwm() - base)
"""


def peak_bytes(call: str) -> float:
    """Growth of the peak resident set (bytes) of ``call`` in a fresh interpreter.

    Linux's ``VmHWM`` (not ``ru_maxrss``, which a child inherits from its parent across exec).
    """
    root = str(Path(__file__).resolve().parents[1])
    res = subprocess.run([sys.executable, "-c", _PEAK.format(root=root, call=call)],
                         capture_output=True, text=True, check=True)
    return float(res.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--profile", action="store_true", help="print where ingest spends time")
    ap.add_argument("--mat", action="store_true", help="also time a QTM MAT v7 mocap file")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "session"
        folder.mkdir()
        t0 = time.perf_counter()
        sizes = write_session(folder, args.minutes)
        tsv = folder / "trial_3d.tsv"
        print(f"session: {args.minutes:g} min, {len(MARKERS)} markers at {RATE} Hz "
              f"({int(sizes['mocap_time'] // 8)} frames, {int(sizes['gap_samples'])} gap "
              f"samples), force 6 ch at {FORCE_RATE} Hz; TSV {tsv.stat().st_size / 1e6:.0f} MB, "
              f"CSV {(folder / 'force.csv').stat().st_size / 1e6:.0f} MB "
              f"(written in {time.perf_counter() - t0:.1f} s)")
        out, rrd = Path(tmp) / "out.mcap", Path(tmp) / "out.rrd"
        rounds = []        # interleaved, so that each round's peers see the same machine load
        for _ in range(args.repeats):
            rounds.append((timed(lambda: bare_parse(tsv)),
                           timed(lambda: ingest(folder, out, None), (out,)),
                           timed(lambda: ingest(folder, out, rrd), (out, rrd))))
        t_bare, t_ingest, t_rrd = (statistics.median(r[i] for r in rounds) for i in range(3))
        print(f"bare pandas.read_csv of the TSV data block: {t_bare:7.2f} s (median of "
              f"{args.repeats}; rounds {', '.join(f'{r[0]:.2f}' for r in rounds)})")
        print(f"run_ingest, no recording:                   {t_ingest:7.2f} s   "
              f"ratio {t_ingest / t_bare:.2f}x (target <= 1.5x); per round "
              f"{', '.join(f'{r[1] / r[0]:.2f}' for r in rounds)}")
        print(f"run_ingest, with recording:                 {t_rrd:7.2f} s   "
              f"ratio {t_rrd / t_bare:.2f}x; per round "
              f"{', '.join(f'{r[2] / r[0]:.2f}' for r in rounds)}; recording "
              f"{rrd.stat().st_size / 1e6:.0f} MB")
        print(f"MCAP {out.stat().st_size / 1e6:.0f} MB")
        parsed = sum(v for k, v in sizes.items() if k != "gap_samples")
        out.unlink()
        call_ingest = f"b.ingest(b.Path({str(folder)!r}), b.Path({str(out)!r}), None)"
        call_bare = f"b.bare_parse(b.Path({str(tsv)!r}))"
        p_ingest, p_bare = peak_bytes(call_ingest), peak_bytes(call_bare)
        print(f"parsed arrays (positions, force, times): {parsed / 1e6:7.0f} MB")
        print(f"peak memory growth, ingest:             {p_ingest / 1e6:7.0f} MB   "
              f"ratio {p_ingest / parsed:.2f}x (target <= 3x)")
        print(f"peak memory growth, bare parse:         {p_bare / 1e6:7.0f} MB   "
              f"ratio {p_bare / parsed:.2f}x")
        if args.mat:
            mat = write_mat_session(folder, Path(tmp) / "session_mat")
            pairs = [(timed(lambda: bare_loadmat(mat)),
                      timed(lambda: ingest(mat.parent, out, None), (out,)))
                     for _ in range(args.repeats)]
            t_load, t_mat = (statistics.median(p[i] for p in pairs) for i in range(2))
            print(f"QTM MAT v7 ({mat.stat().st_size / 1e6:.0f} MB): bare scipy.io.loadmat "
                  f"{t_load:.2f} s, run_ingest {t_mat:.2f} s, ratio {t_mat / t_load:.2f}x; "
                  f"per round {', '.join(f'{b / a:.2f}' for a, b in pairs)}")
        if args.profile:
            prof = cProfile.Profile()
            prof.runcall(ingest, folder, out, None)
            text = io.StringIO()
            pstats.Stats(prof, stream=text).sort_stats("cumulative").print_stats(25)
            print(text.getvalue())


if __name__ == "__main__":
    main()

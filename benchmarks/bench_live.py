"""How `pipeline live` keeps up: a twin session replayed over QTM's real-time protocol by
`pipeline replay` (its own process, as QTM is), recorded live, counted and timed.

For the session (``--minutes`` of presses, the force through QTM's analog board at 1 kHz,
markers at 500 Hz) replayed at ``--speed`` times real time, prints:

* frames: sent by the server, received by the client, skipped by number (dropped), and that
  the MCAP holds every one of them;
* latency: per frame, from the client's hand-over of the decoded frame to the end of its work
  (the journal, the tip's fit, the force tared and flagged, the presses, the view's log calls,
  and with ``--model RUN`` the model's answer while a press goes on), median and p99 in ms,
  for each session of ``--runs``: ``model`` (the recording and the model), ``view`` (the
  recording), ``plain`` (neither), each its own replay;
* lag: the wall time of the live session against the recording's own duration / speed;
* states: those taken live (``states.h5``) against ``pipeline sync`` + ``pipeline extract`` on
  the session's MCAP afterwards: how many, whether the presses, levels and locations are the
  same, and the largest difference of a point (mm) and of a force (N).

The host's speed figure (``../shared/tools/host_speed.py``) is printed beside, as for every
wall time here. Run: ``python benchmarks/bench_live.py [--minutes 10] [--speed 1]
[--runs model,view,plain --model RUN] [--workdir DIR]``.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from core.progress import set_quiet
from data_schema.hdf5 import read_h5
from data_schema.states import STATES
from extract.extract_params import ExtractParams
from extract.extract_stage import run_extract
from ingest.mcap_io import read_raw_mcap
from live.session.live_params import LiveParams
from live.session.live_stage import MCAP_NAME, RRD_NAME, STATES_NAME, LiveSummary, run_live
from sim.twin.synth_params import SynthParams
from sim.twin.synth_stage import run_synth
from sync.sync_params import SyncParams
from sync.sync_stage import run_sync

PRESS_S = 5.9                  # a twin press with its rest, about
MAX_LOCATIONS = 15             # places 15 mm apart that fit on the twin's phantom
ROOT = Path(__file__).resolve().parents[1]


def replay(session: Path, speed: float) -> tuple[subprocess.Popen, int]:
    """`pipeline replay` of ``session`` in its own process, serving one client; the port it
    chose, from its "serving" line."""
    proc = subprocess.Popen([sys.executable, "-m", "pipeline", "replay", str(session),
                             "--port", "0", "--speed", str(speed), "--max-clients", "1"],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    for line in proc.stderr:
        if "serving QTM RT on " in line:
            return proc, int(line.split("serving QTM RT on ")[1].split()[0].rsplit(":", 1)[1])
    raise RuntimeError(f"the replay did not start: {proc.communicate()}")


def record(session: Path, out: Path, speed: float, view: bool, model: Path | None
           ) -> tuple[LiveSummary, int]:
    """One live session of the replayed ``session``: its summary and the frames sent."""
    proc, port = replay(session, speed)
    summary = run_live(session, out, LiveParams(port=port, timeout_s=20, model=model),
                       out / RRD_NAME if view else None)
    stdout, _ = proc.communicate(timeout=60)
    sent = int(stdout.split(" frames sent")[0].rsplit(" ", 1)[-1].replace(",", ""))
    return summary, sent


def report(name: str, s: LiveSummary, sent: int, duration_s: float, speed: float) -> None:
    held = read_raw_mcap(s.mcap).markers.frames
    lat = s.latency_ms
    print(f"{name}: frames sent {sent}, received {s.counts.frames}, skipped "
          f"{s.counts.skipped}, in the MCAP {held} ({'all' if held == sent else 'NOT all'}); "
          f"latency median {np.median(lat):.3f} ms, p99 {np.percentile(lat, 99):.3f} ms, "
          f"max {lat.max():.2f} ms (targets 5 / 20); wall {s.seconds:.1f} s for "
          f"{duration_s / speed:.1f} s of replay (lag {s.seconds - duration_s / speed:+.1f} s);"
          f" ended: {s.ended}")


def compare_states(out: Path) -> None:
    """The states taken live against sync's and extract's on the MCAP afterwards."""
    run_sync(out / MCAP_NAME, out / "offline_synced.h5", SyncParams(), None)
    run_extract([out / "offline_synced.h5"], out / "offline_states.h5", ExtractParams(), None)
    live, _ = read_h5(out / STATES_NAME, STATES)
    offline, _ = read_h5(out / "offline_states.h5", STATES)
    keys = ("states/step", "states/sequence", "states/location")
    same = all(np.array_equal(live[k], offline[k]) for k in keys)
    n = len(live["states/step"])
    if not same:
        print(f"states: {n} live, {len(offline['states/step'])} offline: NOT the same presses "
              "and levels")
        return
    points = np.nanmax(np.abs(live["states/points"] - offline["states/points"])) * 1e3
    force = np.max(np.abs(live["states/force"] - offline["states/force"]))
    print(f"states: {n} live = {n} offline, the same presses, levels and locations; points "
          f"within {points:.4f} mm (target 0.05), forces within {force:.2g} N")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--speed", type=float, default=1.0)
    ap.add_argument("--workdir", type=Path, default=None)
    ap.add_argument("--model", type=Path, default=None,
                    help="a run trained on the twin's markers (e.g. the demo's runs/exp_tl_fold0)")
    ap.add_argument("--runs", default="view,plain",
                    help="which sessions: model (the recording and --model), view (the "
                         "recording), plain (neither)")
    a = ap.parse_args()
    set_quiet(True)
    work = a.workdir or Path(tempfile.mkdtemp(prefix="bench_live_"))
    presses = max(1, round(a.minutes * 60 / PRESS_S))
    locations = max(1, min(MAX_LOCATIONS, presses // 4))
    session = run_synth(None, work / "session", SynthParams(
        seed=0, locations=locations, repeats=max(1, round(presses / locations)),
        force_via="analog"))
    host = subprocess.run([sys.executable, str(ROOT.parent / "shared/tools/host_speed.py")],
                          capture_output=True, text=True).stdout.strip()
    print(f"host: {host or 'host_speed.py not found'}; {presses} presses, speed {a.speed:g}x")
    runs = {"model": ("with the recording and the model", True, a.model),
            "view": ("with the recording", True, None), "plain": ("without", False, None)}
    for key in a.runs.split(","):
        name, view, model = runs[key]
        out = work / f"live_{key}"
        s, sent = record(session, out, a.speed, view, model)
        report(name, s, sent, sent / 500.0, a.speed)
        compare_states(out)


if __name__ == "__main__":
    main()

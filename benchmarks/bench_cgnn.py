"""Speed of the cGNN: our dense layer against PyTorch Geometric's EdgeConv with the same weights.

The peer is the same network (same widths, same weights, same heads) with each graph layer
done the PyG way: kNN from torch (cdist + topk) turned into an edge list, then
``torch_geometric.nn.EdgeConv(nn, aggr="mean")``, which runs the whole MLP once per edge. Ours
applies the first linear per point before gathering and the second after the mean (same
function: tests/train/model/test_cgnn.py checks it against PyG within 1e-5).

Measured in one run, medians over repeats:
- batch-1 latency through :class:`train.Predictor` (ONNX Runtime and torch backends) at 26,
  1024 and 4096 points, for the paper's network and for ours with tip offsets (the recipe):
  ``predict``, ``predict_force`` and ``predict`` in region mode (the default radius) on a mesh
  pressed again (same points, new press: the predictor's scene is known), ``predict`` on a new
  mesh every call (nothing kept), and the peer behind the same SI numpy interface; the ratio
  is peer / ours. The paper's network reads the press in its heads only, so on a known mesh
  only its heads run (:mod:`train.inference.predictor`); with tip offsets the whole network runs;
- where a warm ``predict`` of the tip-offset network spends its time: the predictor's checks
  against the network, and the network's heaviest operators (ONNX Runtime's profiler);
- training samples/s at batch 32 x 1024 points (forward, backward, and the trainer's fused
  Adam step for both), the part of a step both share (heads, loss, Adam: it bounds the ratio),
  and where the time of one of our steps goes (torch.profiler, top operators);
- with ``--device cuda``: the same on the GPU, plus batch-1 latency replayed as a CUDA graph.

    python benchmarks/bench_cgnn.py [--threads 2] [--device cpu|cuda] [--repeats 200]
"""

from __future__ import annotations

import argparse
import io
import itertools
import json
import statistics
import tempfile
import time
from collections import Counter
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np
import torch
from torch import nn

from train.inference.predictor import DEFAULT_REGION, Predictor
from train.inference.si_model import ENTRIES, SIModel, to_onnx
from train.model.cgnn import CGNN
from train.model.config import CGNNConfig, Offsets
from train.model.normalise import Envelope, Normaliser
from train.model.si_units import deformed, newtons
from train.training.loop import adam


def pyg_knn_edges(x: torch.Tensor, k: int) -> torch.Tensor:
    """Edge list (2, B*N*k) j -> i of each point's k nearest (itself included), batch-offset."""
    b, n, _ = x.shape
    idx = torch.cdist(x, x).topk(k, dim=-1, largest=False).indices            # (B, N, k)
    offset = (torch.arange(b, device=x.device) * n).view(b, 1, 1)
    dst = torch.arange(n, device=x.device).view(1, n, 1).expand(b, n, k) + offset
    return torch.stack([(idx + offset).reshape(-1), dst.reshape(-1)])


class PygPeer(nn.Module):
    """Our CGNN with its graph layers run by PyG's EdgeConv (shares the weights)."""

    def __init__(self, model: CGNN) -> None:
        super().__init__()
        from torch_geometric.nn import EdgeConv

        self.model = model
        state = {k: v.clone() for k, v in model.state_dict().items()}
        self.convs = nn.ModuleList(EdgeConv(c.mlp, aggr="mean") for c in model.convs)
        model.load_state_dict(state)          # EdgeConv re-initialises the MLP it is given

    def forward(self, points: torch.Tensor, cond: torch.Tensor) -> tuple[torch.Tensor, ...]:
        b, n, _ = points.shape
        x, outs = self.model.inputs(points, cond), []
        for conv in self.convs:
            edges = pyg_knn_edges(x.detach(), self.model.config.k)
            x = torch.relu(conv(x.reshape(b * n, -1), edges)).reshape(b, n, -1)
            outs.append(x)
        return self.model.heads(torch.cat(outs, -1), cond, None,
                                self.model.encoded(points, cond))


def median_ms(fn: Callable[[], object], repeats: int, sync: Callable[[], None]) -> float:
    """Median wall time of ``fn`` in milliseconds, after a warm-up of a tenth of the repeats
    and at least 50 ms (the steady state of a loop: another call's threads have settled)."""
    start, calls = time.perf_counter(), 0
    while calls < max(3, repeats // 10) or time.perf_counter() - start < 0.05:
        fn()
        calls += 1
    sync()
    times = []
    for _ in range(repeats):
        tic = time.perf_counter()
        fn()
        sync()
        times.append(time.perf_counter() - tic)
    return statistics.median(times) * 1e3


# a 100 mm surface's statistics, with a training envelope (presses of 1-20 mm from up to 5 mm
# above the surface) so that every call checks its press against it, as a checkpoint's does
ENVELOPE = Envelope(press_min=0.001, press_max=0.02, tip_lowest=-0.02, gap_max=0.005,
                    force_min=-1e6, force_max=1e6, top=0.001)
NORM = Normaliser((0.05, 0.05, 0.0), 0.04, 0.002, 0.5, 0.07, ENVELOPE)
PRESS = np.array([0.05, 0.05, 0.002, 0.05, 0.05, -0.01], np.float32)  # 12 mm at the centre


def circle(places: int = 64, radius: float = 0.02) -> list[np.ndarray]:
    """A moving tip: ``PRESS`` at ``places`` points of a circle about the centre, in turn
    (a haptic loop's tip moves between calls, so each call is a new press)."""
    turn = np.linspace(0.0, 2 * np.pi, places, endpoint=False)
    shift = np.stack([np.cos(turn), np.sin(turn), np.zeros(places)], 1) * radius
    return [(PRESS + np.tile(s, 2)).astype(np.float32) for s in shift]


def moving() -> Callable[[], np.ndarray]:
    """Each call the next press of :func:`circle`."""
    return partial(next, itertools.cycle(circle()))


def surface(n: int, grid: bool) -> np.ndarray:
    """``n`` points on the 100 mm surface: a regular grid, or random (seeded)."""
    if grid:
        side = np.linspace(0.0, 0.1, round(n ** 0.5), dtype=np.float32)
        x, y = np.meshgrid(side, side)
        return np.stack([x.ravel(), y.ravel(), np.zeros(x.size, np.float32)], 1)
    pts = np.random.default_rng(n).uniform(0.0, 0.1, (n, 3)).astype(np.float32)
    pts[:, 2] = 0.0
    return pts


class PeerPredictor:
    """The PyG peer behind the same SI interface as ours: numpy in, normalise, run, numpy out."""

    def __init__(self, peer: PygPeer, device: torch.device) -> None:
        self.peer, self.device = peer, device

    @torch.inference_mode()
    def predict(self, points: np.ndarray, condition: np.ndarray) -> tuple[np.ndarray, float]:
        p = torch.from_numpy(points).to(self.device)
        c = torch.from_numpy(condition).to(self.device)
        disp, df = self.peer(NORM.points(p)[None], NORM.condition(c)[None])
        return deformed(p, disp[0], NORM).cpu().numpy(), float(newtons(df[0], NORM))


# The networks timed: the tip's offsets nowhere, in the heads, in the first layer
NETWORKS = {"the paper's network": CGNNConfig(),
            "head offsets": CGNNConfig(offsets=Offsets.HEADS),
            "tip offsets": CGNNConfig(offsets=Offsets.GRAPH)}


READS = {True: "its graph layers read the press: every press runs them",
         False: "its graph layers do not read the press: a known mesh runs the heads alone"}


def latency(device: torch.device, repeats: int, sync: Callable[[], None]) -> None:
    """Batch-1 latency through the predictor, for each of :data:`NETWORKS` (a mesh pressed
    again with a moving tip and with one press repeated: the scene is reused; and a new mesh
    every call)."""
    backends = ("onnx", "torch") if device.type == "cpu" else ("torch",)
    print(f"batch-1 latency through Predictor [ms] (median of >= 30); ratio = PyG peer / "
          f"ours ({backends[0]}); region = {DEFAULT_REGION * 1e3:.0f} mm; a known mesh with a "
          "moving tip (a new press each call) unless 'same' (one press repeated); 'new' = a "
          "new mesh every call (nothing cached):")
    for name, cfg in NETWORKS.items():
        torch.manual_seed(0)
        model = CGNN(cfg).to(device).eval()
        si = SIModel(model, NORM)
        ours = {b: Predictor(si, device, b) for b in backends}
        them = PeerPredictor(PygPeer(model).to(device).eval(), device)
        print(f" {name} ({READS[not cfg.offsets.press_independent]}):")
        for n, grid in ((26, False), (1024, False), (1024, True), (4096, True)):
            row = scene_row(ours, them, surface(n, grid), max(30, repeats * 26 // n), sync)
            ratio = {what: row["PyG peer"] / row[f"{backends[0]} {what}"]
                     for what in ("predict", "same", "region", "new")}
            print(f"  N={n:5d} {'grid' if grid else 'random':6s} "
                  + "  ".join(f"{k} {v:7.3f}" for k, v in row.items())
                  + f"  ratio {ratio['predict']:5.2f}x (same press {ratio['same']:5.2f}x, "
                    f"region {ratio['region']:5.1f}x, new {ratio['new']:4.1f}x)")
        if device.type == "cpu":
            where_the_time_goes(ours["onnx"], si, repeats)
    if device.type == "cpu" and torch.get_num_threads() > 1:
        thread_table(repeats)


def scene_row(ours: dict[str, Predictor], them: PeerPredictor, pts: np.ndarray, reps: int,
              sync: Callable[[], None]) -> dict[str, float]:
    """Median ms of each backend's predict, predict_force and region predict on a known mesh
    with a moving tip, of predict and predict_force with one press repeated ("same"), and of
    predict on a new mesh each call (two meshes in turn); and the peer's, with the moving tip."""
    moved = pts.copy()
    moved[0, 2] += np.float32(1e-4)
    turn, press = [pts, moved], moving()      # the meshes in turn: each call is a new scene

    def new(p: Predictor) -> None:
        turn.reverse()
        p.predict(turn[0], press())

    calls = {"predict": lambda p: p.predict(pts, press()),
             "force": lambda p: p.predict_force(pts, press()),
             "region": lambda p: p.predict(pts, press(), region=DEFAULT_REGION),
             "same": lambda p: p.predict(pts, PRESS),
             "force same": lambda p: p.predict_force(pts, PRESS),
             "new": new}
    row = {f"{b} {what}": median_ms(lambda p=p, fn=fn: fn(p), reps, sync)
           for b, p in ours.items() for what, fn in calls.items()}
    row["PyG peer"] = median_ms(lambda: them.predict(pts, press()), reps, sync)
    return row


def feed(pred: Predictor, pts: np.ndarray, entry: str) -> tuple[np.ndarray, ...]:
    """The inputs of ``entry`` for a press on the known scene of ``pts``, as the predictor
    passes them."""
    pred.predict(pts, PRESS)                                    # the scene is known
    scene = pred._scene_of(pts)
    disp, force = scene.terms if scene.terms is not None else (None, None)
    made = {"points": scene.points[None], "condition": PRESS[None], "surface": scene.points[None],
            "neighbours": scene.neighbours[None], "disp_terms": disp, "force_terms": force}
    return tuple(made[name] for name in ENTRIES[entry].inputs)


def where_the_time_goes(pred: Predictor, si: SIModel, repeats: int) -> None:
    """Split one warm ``predict`` on a known mesh with a moving tip into the predictor's
    checks (the envelope's among them) and the network, and name the network's heaviest
    operators (ONNX Runtime's own profiler on the same graph)."""
    entry = "pressed" if pred.press_independent else "full"
    print(f"  where a known mesh's predict goes (onnx, a moving tip, entry {entry}) [ms]:")
    for n in (26, 1024):
        split_call(pred, si, entry, surface(n, False), repeats)


def split_call(pred: Predictor, si: SIModel, entry: str, pts: np.ndarray, repeats: int
               ) -> None:
    """One line of :func:`where_the_time_goes`: the call, its checks, the envelope's, the
    network and its heaviest operators."""
    press, inputs = moving(), feed(pred, pts, entry)
    scene = pred._scene_of(pts)
    checks = median_ms(lambda: pred._press(pts, press(), None), repeats, lambda: None)
    def beyond() -> list[str]:
        v = press().tolist()
        return pred._beyond(v[:3], v[3:], scene)

    envelope = median_ms(beyond, repeats, lambda: None)
    net = median_ms(partial(pred.backend.run, entry, *inputs), repeats, lambda: None)
    whole = median_ms(lambda: pred.predict(pts, press()), repeats, lambda: None)
    top = ", ".join(f"{op} {share:.0f}%" for op, share in onnx_operators(si, entry, inputs)[:6])
    print(f"   N={len(pts):5d}: call {whole:6.3f} = checks {checks:6.3f} (the envelope's "
          f"{envelope:6.4f}, {100 * envelope / whole:.1f}% of the call) + network {net:6.3f} + "
          f"the rest; its operators: {top}")


def thread_table(repeats: int) -> None:
    """Each ONNX entry of the recipe's network with one intra-op thread against torch's
    count: what :class:`train.inference.backends.OnnxBackend`'s rule is measured on (best of
    the repeats: the steady state a loop reaches on a shared host's quiet moments)."""
    import onnxruntime as ort

    threads = torch.get_num_threads()
    torch.manual_seed(0)
    si = SIModel(CGNN(NETWORKS["head offsets"]).eval(), NORM)
    pred = Predictor(si, torch.device("cpu"), "onnx")
    print(f"ONNX Runtime threads, the recipe's network [ms] (best of {repeats}): "
          f"1 thread / {threads} threads")
    for entry in pred.backend.sessions:
        buf = io.BytesIO()
        to_onnx(si, buf, entry)
        sessions = {}
        for t in (1, threads):
            opts = ort.SessionOptions()
            opts.intra_op_num_threads, opts.inter_op_num_threads = t, 1
            sessions[t] = ort.InferenceSession(buf.getvalue(), opts,
                                               providers=["CPUExecutionProvider"])
        for n in (26, 256, 1024):
            given = dict(zip(ENTRIES[entry].inputs, feed(pred, surface(n, False), entry),
                             strict=True))
            inputs = {name: given[name] for name in pred.backend.inputs[entry]}
            best = [min_ms(partial(sessions[t].run, None, inputs), repeats)
                    for t in (1, threads)]
            print(f"  {entry:22s} N={n:5d}: {best[0]:7.3f} / {best[1]:7.3f}")


def min_ms(fn: Callable[[], object], repeats: int) -> float:
    """The best wall time of ``fn`` over ``repeats`` calls, ms (a shared host's quiet moments)."""
    fn()
    times = []
    for _ in range(repeats):
        tic = time.perf_counter()
        fn()
        times.append(time.perf_counter() - tic)
    return min(times) * 1e3


def onnx_operators(si: SIModel, entry: str, inputs: tuple[np.ndarray, ...], runs: int = 50
                   ) -> list[tuple[str, float]]:
    """ONNX Runtime's operators by their share (%) of ``entry``'s kernel time."""
    import onnxruntime as ort

    buf = io.BytesIO()
    to_onnx(si, buf, entry)
    with tempfile.TemporaryDirectory() as tmp:
        opts = ort.SessionOptions()
        opts.intra_op_num_threads, opts.inter_op_num_threads = torch.get_num_threads(), 1
        opts.enable_profiling, opts.profile_file_prefix = True, f"{tmp}/ort"
        session = ort.InferenceSession(buf.getvalue(), opts, providers=["CPUExecutionProvider"])
        given = dict(zip(ENTRIES[entry].inputs, inputs, strict=True))
        names = [i.name for i in session.get_inputs()]
        for _ in range(runs):
            session.run(None, {name: given[name] for name in names})
        events = json.loads(Path(session.end_profiling()).read_text())
    spent = Counter()
    for e in events:
        if e.get("cat") == "Node" and e["name"].endswith("_kernel_time"):
            spent[e["args"]["op_name"]] += e["dur"]
    total = sum(spent.values())
    return [(op, 100 * t / total) for op, t in spent.most_common()]


def cuda_graph_latency(model: CGNN, repeats: int) -> None:
    print("batch-1 latency replayed as a CUDA graph [ms] (median):")
    for n in (26, 1024):
        p, c = torch.rand(1, n, 3, device="cuda"), torch.rand(1, 6, device="cuda")
        s = torch.cuda.Stream()
        s.wait_stream(torch.cuda.current_stream())
        with torch.cuda.stream(s), torch.inference_mode():
            for _ in range(3):
                model(p, c)
        torch.cuda.current_stream().wait_stream(s)
        graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(graph), torch.inference_mode():
            model(p, c)
        t = median_ms(graph.replay, repeats, torch.cuda.synchronize)
        print(f"  N={n:5d}: {t:7.3f}")


def training(device: torch.device, steps: int, sync: Callable[[], None]) -> None:
    """Training speed of each of :data:`NETWORKS` against its peer; where the time of the
    last one's step goes."""
    print("training samples/s at batch 32 x 1024 points (forward + backward + Adam):")
    for name, cfg in NETWORKS.items():
        torch.manual_seed(0)
        model = CGNN(cfg).to(device).train()
        print(f" {name}:")
        training_row(model, PygPeer(model).to(device).train(), device, steps, sync)


def training_row(model: CGNN, peer: nn.Module, device: torch.device, steps: int,
                 sync: Callable[[], None], batch: int = 32, n: int = 1024) -> None:
    """Samples/s of ours and the peer, and what the two share: the heads, the loss and Adam
    (timed on fixed features), which bounds the ratio even if graph layers cost nothing."""
    x = torch.rand(batch, n, 3, device=device)
    c, y = torch.rand(batch, 6, device=device), torch.rand(batch, n, 3, device=device)
    f = torch.rand(batch, device=device)
    local = torch.rand(batch, n, sum(o for _, o in model.config.edge_widths), device=device,
                       requires_grad=True)
    opt = adam(model.parameters(), 1e-4)

    def step(forward: Callable[[], tuple[torch.Tensor, torch.Tensor]]) -> None:
        d, df = forward()
        loss = 88 * (d - y).norm(dim=-1).mean() + ((df - f) ** 2).mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()

    ms = {name: median_ms(partial(step, fn), steps, sync) for name, fn in (
        ("ours", partial(model, x, c)), ("PyG peer", partial(peer, x, c)),
        ("shared", lambda: model.heads(local, c, None, model.encoded(x, c))))}
    print(f"  ours {batch / ms['ours'] * 1e3:8.1f}  PyG peer {batch / ms['PyG peer'] * 1e3:8.1f}"
          f"  ratio {ms['PyG peer'] / ms['ours']:5.2f}x; per step: ours {ms['ours']:.0f} ms, "
          f"peer {ms['PyG peer']:.0f} ms, shared by both (heads, loss, Adam) {ms['shared']:.0f}"
          f" ms: with free graph layers the ratio could reach {ms['PyG peer'] / ms['shared']:.1f}x")
    if device.type == "cpu" and model.offsets.in_heads:     # the recipe's network
        profile_step(model, x, c, y, f)


def profile_step(model: CGNN, x, c, y, f) -> None:
    from torch.profiler import ProfilerActivity, profile

    opt = adam(model.parameters(), 1e-4)
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        d, df = model(x, c)
        loss = 88 * (d - y).norm(dim=-1).mean() + ((df - f) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
    total = sum(e.self_cpu_time_total for e in prof.key_averages())
    print("  where one of our training steps goes (self CPU time, top operators):")
    for e in sorted(prof.key_averages(), key=lambda e: -e.self_cpu_time_total)[:8]:
        print(f"    {e.key:32s} {e.self_cpu_time_total / 1e3:8.1f} ms "
              f"{100 * e.self_cpu_time_total / total:5.1f}%")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--device", choices=["cpu", "cuda"], default="cpu")
    ap.add_argument("--repeats", type=int, default=200)
    ap.add_argument("--train-steps", type=int, default=6)
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    device = torch.device(a.device)
    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)
    print(f"device {device}"
          + (f" ({torch.cuda.get_device_name()})" if device.type == "cuda" else
             f", {torch.get_num_threads()} threads") + f", torch {torch.__version__}")
    latency(device, a.repeats, sync)
    if device.type == "cuda":
        torch.manual_seed(0)
        cuda_graph_latency(CGNN(CGNNConfig()).to(device).eval(), a.repeats)
    training(device, a.train_steps, sync)


if __name__ == "__main__":
    main()

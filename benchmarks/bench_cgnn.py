"""Speed of the cGNN: our dense layer against PyTorch Geometric's EdgeConv with the same weights.

The peer is the same network (same widths, same weights, same heads) with each graph layer
done the PyG way: kNN from torch (cdist + topk) turned into an edge list, then
``torch_geometric.nn.EdgeConv(nn, aggr="mean")``, which runs the whole MLP once per edge. Ours
applies the first linear per point before gathering and the second after the mean (same
function: tests/test_cgnn_model.py checks it against PyG within 1e-5).

Measured in one run, medians over repeats:
- batch-1 latency at 26 and 1024 points (ours, peer, ratio), and ``forward_force`` alone;
- training samples/s at batch 32 x 1024 points (forward, backward, Adam step), and where the
  time of one of our steps goes (torch.profiler, top operators);
- the ONNX export's latency in onnxruntime beside torch's;
- with ``--device cuda``: the same on the GPU, plus batch-1 latency replayed as a CUDA graph.

    python benchmarks/bench_cgnn.py [--threads 2] [--device cpu|cuda] [--repeats 200]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import torch
from torch import nn

from train.model import CGNN, CGNNConfig, Features


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
        x, outs = points, []
        for conv in self.convs:
            edges = pyg_knn_edges(x.detach(), self.model.config.k)
            x = torch.relu(conv(x.reshape(b * n, -1), edges)).reshape(b, n, -1)
            outs.append(x)
        f = Features(torch.cat(outs, -1), cond)
        return self.model.displacement(f), self.model.force(f)


def median_ms(fn: Callable[[], object], repeats: int, sync: Callable[[], None]) -> float:
    """Median wall time of ``fn`` in milliseconds (after warm-up)."""
    for _ in range(max(3, repeats // 10)):
        fn()
    sync()
    times = []
    for _ in range(repeats):
        tic = time.perf_counter()
        fn()
        sync()
        times.append(time.perf_counter() - tic)
    return statistics.median(times) * 1e3


def latency(model: CGNN, peer: PygPeer, device: torch.device, repeats: int,
            sync: Callable[[], None]) -> None:
    print("batch-1 latency [ms] (median):")
    for n in (26, 1024):
        p, c = torch.rand(1, n, 3, device=device), torch.rand(1, 6, device=device)
        with torch.inference_mode():
            ours = median_ms(lambda p=p, c=c: model(p, c), repeats, sync)
            force = median_ms(lambda p=p, c=c: model.forward_force(p, c), repeats, sync)
            theirs = median_ms(lambda p=p, c=c: peer(p, c), repeats, sync)
        print(f"  N={n:5d}: ours {ours:7.3f}  force only {force:7.3f}  PyG peer {theirs:7.3f}"
              f"  ratio {theirs / ours:5.2f}x")


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


def training(model: CGNN, peer: nn.Module, device: torch.device, steps: int,
             sync: Callable[[], None], batch: int = 32, n: int = 1024) -> None:
    x = torch.rand(batch, n, 3, device=device)
    c, y = torch.rand(batch, 6, device=device), torch.rand(batch, n, 3, device=device)
    f = torch.rand(batch, device=device)
    print(f"training samples/s at batch {batch} x {n} points (forward + backward + Adam):")
    rates = {}
    for name, net in (("ours", model), ("PyG peer", peer)):
        opt = torch.optim.Adam(model.parameters(), lr=1e-4)

        def step(net=net, opt=opt) -> None:
            d, df = net(x, c)
            loss = 88 * (d - y).norm(dim=-1).mean() + ((df - f) ** 2).mean()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()

        rates[name] = batch / (median_ms(step, steps, sync) / 1e3)
    print(f"  ours {rates['ours']:8.1f}  PyG peer {rates['PyG peer']:8.1f}  ratio "
          f"{rates['ours'] / rates['PyG peer']:5.2f}x")
    if device.type == "cpu":
        profile_step(model, x, c, y, f)


def profile_step(model: CGNN, x, c, y, f) -> None:
    from torch.profiler import ProfilerActivity, profile

    opt = torch.optim.Adam(model.parameters(), lr=1e-4)
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


def onnx_latency(model: CGNN, repeats: int) -> None:
    import onnxruntime as ort

    from train.export import SIModel
    from train.normalise import Normaliser

    norm = Normaliser((0.05, 0.05, 0.0), 0.04, 0.002, 0.5, 0.07)
    si = SIModel(model, norm).eval()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "m.onnx"
        torch.onnx.export(si, (torch.rand(1, 26, 3), torch.rand(1, 6)), str(path),
                          input_names=["points", "condition"], output_names=["deformed", "dforce"],
                          opset_version=17, dynamic_axes={"points": {1: "N"}, "deformed": {1: "N"}},
                          dynamo=False)
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = torch.get_num_threads()
        sess = ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
        print("ONNX (onnxruntime, CPU) against torch, batch 1 [ms] (median):")
        for n in (26, 1024):
            p, c = torch.rand(1, n, 3), torch.rand(1, 6)
            feed = {"points": p.numpy(), "condition": c.numpy()}
            t_onnx = median_ms(lambda feed=feed: sess.run(None, feed), repeats, lambda: None)
            with torch.inference_mode():
                t_torch = median_ms(lambda p=p, c=c: si(p, c), repeats, lambda: None)
            print(f"  N={n:5d}: onnxruntime {t_onnx:7.3f}  torch {t_torch:7.3f}")


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
    torch.manual_seed(0)
    model = CGNN(CGNNConfig()).to(device).eval()
    peer = PygPeer(model).to(device).eval()
    print(f"device {device}"
          + (f" ({torch.cuda.get_device_name()})" if device.type == "cuda" else
             f", {torch.get_num_threads()} threads") + f", torch {torch.__version__}")
    latency(model, peer, device, a.repeats, sync)
    if device.type == "cuda":
        cuda_graph_latency(model, a.repeats)
    training(model.train(), peer.train(), device, a.train_steps, sync)
    if device.type == "cpu":
        onnx_latency(model.eval(), a.repeats)


if __name__ == "__main__":
    main()

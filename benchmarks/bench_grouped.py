"""Would training several networks as one batched network make the demo faster? G copies of
the recipe's network (the tip's offsets in the heads) stacked into one, each linear layer a
batched matrix product over the G weights (``torch.bmm``; the kNN over all G x B samples at
once), against the same G networks stepped one after another; and the same G copies run by
``torch.func.vmap`` over ``torch.func.stack_module_state`` (the kNN then ranks a fixed k + 2
candidates on every row, as a traced graph does: vmap cannot branch on the data; up to about
180 points, past which the kNN searches in pieces written in place, which vmap refuses).

    python benchmarks/bench_grouped.py [--groups 2 5] [--steps 40] [--points 26]

One thread; batch 32 per network, as the demo's folds train; each step is forward, backward
and a fused Adam step (the trainer's). The steps alternate between the ways, on the same
batches; printed: the median ms of G steps each way and the ratio sequential / batched, and
first the largest difference between a batched member's output and its own network's (the
stacked network computes the same function). The demo's per-fold training is the case: five
folds' pre-training, or a fold's TL and scratch runs (G = 2).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from unittest import mock

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from train.model import edgeconv  # noqa: E402
from train.model.cgnn import CGNN, pool  # noqa: E402
from train.model.config import CGNNConfig, Offsets  # noqa: E402
from train.model.edgeconv import gather_rows, knn, tiebreak  # noqa: E402
from train.training.loop import adam  # noqa: E402

BATCH = 32
Params = dict[str, torch.Tensor]


def linear(x: torch.Tensor, w: torch.Tensor, b: torch.Tensor | None = None) -> torch.Tensor:
    """G linear layers at once: ``x`` (G, ..., I), ``w`` (G, O, I), ``b`` (G, O)."""
    flat = x.reshape(w.shape[0], -1, x.shape[-1])
    y = torch.bmm(flat, w.transpose(1, 2)) if b is None else \
        torch.baddbmm(b.unsqueeze(1), flat, w.transpose(1, 2))
    return y.reshape(*x.shape[:-1], w.shape[1])


def stacked_forward(p: Params, k: int, pts: torch.Tensor, cond: torch.Tensor
                    ) -> tuple[torch.Tensor, torch.Tensor]:
    """The recipe's CGNN (train/model/cgnn.py) for G networks at once: points (G, B, N, 3),
    C (G, B, 6) -> displacement (G, B, N, 3), change of force (G, B)."""
    g, b, n, _ = pts.shape
    key, x, outs = tiebreak(pts).flatten(0, 1), pts, []
    for i in range(3):
        w1, f = p[f"convs.{i}.mlp.0.weight"], x.shape[-1]
        own = linear(x, w1[..., :f] - w1[..., f:], p[f"convs.{i}.mlp.0.bias"])
        nbr = linear(x, w1[..., f:])
        idx = knn(x.flatten(0, 1), k, None, key)
        hidden = torch.relu(own.flatten(0, 1).unsqueeze(2) + gather_rows(nbr.flatten(0, 1), idx))
        x = torch.relu(linear(hidden.mean(2).view(g, b, n, -1), p[f"convs.{i}.mlp.2.weight"],
                              p[f"convs.{i}.mlp.2.bias"]))
        outs.append(x)
    local = torch.cat(outs, -1)
    d = pts.unsqueeze(3) - cond.view(g, b, 1, 2, 3)
    e = torch.relu(linear(torch.cat([d.flatten(3), torch.linalg.vector_norm(d, dim=-1)], -1),
                          p["encoder.weight"], p["encoder.bias"]))

    def head(name: str, feats: torch.Tensor, enc: torch.Tensor, layers: int) -> torch.Tensor:
        w, f, width = p[f"{name}.0.weight"], feats.shape[-1], enc.shape[-1]
        y = linear(feats, w[..., :f], p[f"{name}.0.bias"]) + linear(enc, w[..., f:f + width])
        c = linear(cond, w[..., -6:])
        y = y + c.view(g, b, *[1] * (y.dim() - 3), -1)
        for j in range(1, layers):
            y = linear(torch.relu(y), p[f"{name}.{2 * j}.weight"], p[f"{name}.{2 * j}.bias"])
        return y

    pooled = pool(local.flatten(0, 1), None).view(g, b, -1)
    force = head("force_head", pooled, pool(e.flatten(0, 1), None).view(g, b, -1), 4)
    return head("disp_head", local, e, 3), force.squeeze(-1)


def batches(g: int, n: int, gen: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """G batches of random surfaces of n points (normalised units) and presses."""
    pts = torch.rand(g, BATCH, n, 3, generator=gen) * 2 - 1
    pts[..., 2] *= 0.05
    return pts, torch.rand(g, BATCH, 6, generator=gen) * 2 - 1


def loss(disp: torch.Tensor, force: torch.Tensor) -> torch.Tensor:
    """A stand-in for the trainer's loss: as many terms, the same shapes."""
    return disp.square().sum() + force.square().sum()


def compare(g: int, n: int, steps: int) -> None:
    """One row: G networks stacked (bmm), under vmap, and one after another."""
    torch.manual_seed(0)
    config = CGNNConfig(offsets=Offsets.HEADS)
    nets = [CGNN(config) for _ in range(g)]
    names = [name for name, _ in nets[0].named_parameters()]
    stacked = {name: torch.stack([dict(m.named_parameters())[name].detach() for m in nets])
               .requires_grad_() for name in names}
    stacked_opt = torch.optim.Adam(list(stacked.values()), lr=1e-3, fused=True)
    mapped, buffers = torch.func.stack_module_state(nets)
    mapped_opt = torch.optim.Adam(list(mapped.values()), lr=1e-3, fused=True)
    base = CGNN(config).to("meta")
    own_opts = [adam(m, 1e-3) for m in nets]
    gen = torch.Generator().manual_seed(1)
    pts, cond = batches(g, n, gen)
    with torch.no_grad():
        disp, force = stacked_forward(stacked, config.k, pts, cond)
        own = [m(pts[i], cond[i]) for i, m in enumerate(nets)]
        worst = max(max(float((d - disp[i]).abs().max()), float((f - force[i]).abs().max()))
                    for i, (d, f) in enumerate(own))
    print(f" G={g}, N={n}: largest |stacked - own network| {worst:.2g}")

    def one_by_one(pts: torch.Tensor, cond: torch.Tensor) -> None:
        for i, (m, opt) in enumerate(zip(nets, own_opts, strict=True)):
            opt.zero_grad(set_to_none=True)
            loss(*m(pts[i], cond[i])).backward()
            opt.step()

    def as_one(pts: torch.Tensor, cond: torch.Tensor) -> None:
        stacked_opt.zero_grad(set_to_none=True)
        loss(*stacked_forward(stacked, config.k, pts, cond)).backward()
        stacked_opt.step()

    def vmapped(pts: torch.Tensor, cond: torch.Tensor) -> None:
        def call(p: Params, b: Params, x: torch.Tensor, c: torch.Tensor):
            return torch.func.functional_call(base, (p, b), (x, c))
        mapped_opt.zero_grad(set_to_none=True)
        with mock.patch.object(edgeconv, "fixed_width", lambda: True):   # no branches
            out = torch.func.vmap(call)(mapped, buffers, pts, cond)
        loss(*out).backward()
        mapped_opt.step()

    ways: dict[str, Callable[[torch.Tensor, torch.Tensor], None]] = {
        "one after another": one_by_one, "stacked (bmm)": as_one}
    if BATCH * n * n <= edgeconv.BLOCK:        # larger: the kNN's pieces write in place,
        ways["vmap"] = vmapped                 # which vmap refuses
    times: dict[str, list[float]] = {w: [] for w in ways}
    order = list(ways)
    for step in range(steps + 2):
        data = batches(g, n, gen)
        order = order[1:] + order[:1]                      # each way first in turn
        for way in order:
            tic = time.perf_counter()
            ways[way](*data)
            if step >= 2:                                  # the first two warm up
                times[way].append((time.perf_counter() - tic) * 1e3)
    ms = {w: statistics.median(t) for w, t in times.items()}
    seq = ms["one after another"]
    print("  " + "; ".join(f"{w} {v:.1f} ms ({seq / v:.2f}x)" for w, v in ms.items()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--groups", type=int, nargs="+", default=[2, 5])
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--points", type=int, default=26)
    a = ap.parse_args()
    torch.set_num_threads(1)
    print(f"G training steps of batch {BATCH} (forward, backward, fused Adam), one thread, "
          f"torch {torch.__version__}; median ms and speed-up over one after another:")
    for g in a.groups:
        compare(g, a.points, a.steps)


if __name__ == "__main__":
    main()

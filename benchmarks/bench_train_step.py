"""A training step at the demo's size (the recipe's network, batch 32, 26 points, one thread):
where it goes, and what would make the demo's training cheaper.

    python benchmarks/bench_train_step.py [--groups [G ...]] [--steps 40] [--points 26] [--compile]

1. The step's parts (median ms): forward, backward, the optimizer, the weights' average.
2. The optimizer: torch's default Adam and a per-parameter average (the trainer's before
   2026-11-27) against the trainer's (:func:`train.training.loop.adam`, fused, and
   :func:`train.training.loop.update_average`, one call), steps alternating on the same batches.
3. Several networks trained as one: G copies stacked into one network, each linear layer a
   batched matrix product over the G weights (``torch.bmm``; the kNN over all G x B samples at
   once), and the same G copies under ``torch.func.vmap`` of ``stack_module_state`` (the kNN
   then ranks a fixed k + 2 candidates on every row, as a traced graph does: vmap cannot branch
   on the data; only up to about 180 points, past which the kNN searches in pieces written in
   place, which vmap refuses), against the G networks stepped one after another. First the
   largest difference between a stacked member's output and its own network's (the stacked
   network computes the same function). The demo's case: five folds' pre-training (G = 5), or
   a fold's TL and scratch runs (G = 2).
4. With ``--compile``: a step with the network under ``torch.compile`` against the same step
   eager, both with the kNN that ranks a fixed k + 2 candidates (a compiled graph cannot
   branch on the data), and the trainer's eager step beside them (first the compile time and
   the largest difference between the compiled and eager outputs).

The ways run in turn on the same batches, each first in turn; the loss is a stand-in with the
trainer's shapes (the optimizer's and the graph's costs do not depend on it). Printed: medians
and the speed-up over the peer of the same run.
"""

from __future__ import annotations

import argparse
import contextlib
import statistics
import sys
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from types import SimpleNamespace
from unittest import mock

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from train.model import knn as knn_module  # noqa: E402
from train.model.cgnn import CGNN, pool  # noqa: E402
from train.model.config import CGNNConfig, Offsets  # noqa: E402
from train.model.edgeconv import gather_rows  # noqa: E402
from train.model.knn import knn, tiebreak  # noqa: E402
from train.training.loop import adam, update_average  # noqa: E402

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


def timed(ways: dict[str, Callable[[], object]], steps: int, rotate: bool = True,
          between: Callable[[], object] = lambda: None) -> dict[str, float]:
    """Median ms of each way over ``steps`` rounds (after two to warm up); ``between`` runs
    before each round (the next batch). ``rotate``: each way first in turn (ways compared);
    else in their order (the parts of one step)."""
    times: dict[str, list[float]] = {w: [] for w in ways}
    order = list(ways)
    for step in range(steps + 2):
        between()
        if rotate:
            order = order[1:] + order[:1]
        for way in order:
            tic = time.perf_counter()
            ways[way]()
            if step >= 2:
                times[way].append((time.perf_counter() - tic) * 1e3)
    return {w: statistics.median(t) for w, t in times.items()}


Step = Callable[[torch.Tensor, torch.Tensor], None]     # one training step on (points, C)
CONFIG = CGNNConfig(offsets=Offsets.HEADS)              # the recipe's network


def parts_and_optimizer(n: int, steps: int) -> None:
    """Sections 1 and 2: one network's step split into its parts, and the optimizer old and
    new."""
    torch.manual_seed(0)
    net, gen = CGNN(CONFIG), torch.Generator().manual_seed(1)
    run = SimpleNamespace(model=net, averaged=CGNN(CONFIG))
    fused, plain = adam(net.parameters(), 1e-3), torch.optim.Adam(net.parameters(), lr=1e-3)
    average = partial(update_average, run, 0.99)
    pts, cond = batches(1, n, gen)

    def plain_average() -> None:
        with torch.no_grad():
            for avg, w in zip(run.averaged.parameters(), net.parameters(), strict=True):
                avg.lerp_(w, 0.01)

    out: list[tuple[torch.Tensor, torch.Tensor]] = []
    parts = {"forward": lambda: out.append(net(pts[0], cond[0])),
             "backward": lambda: (net.zero_grad(set_to_none=True),
                                  loss(*out.pop()).backward()),
             "Adam, fused": fused.step, "average, one call": average}
    ms = timed(parts, steps, rotate=False)
    print(" one step's parts: " + "; ".join(f"{w} {v:.2f} ms" for w, v in ms.items()))

    def step(opt: torch.optim.Optimizer, then: Callable[[], object]) -> None:
        net.zero_grad(set_to_none=True)
        loss(*net(pts[0], cond[0])).backward()
        opt.step()
        then()

    old, new = timed({"old": partial(step, plain, plain_average),
                      "new": partial(step, fused, average)}, steps * 5).values()
    print(f" a whole step: torch's default Adam and a per-parameter average {old:.2f} ms, the "
          f"trainer's (fused, one call) {new:.2f} ms ({old / new:.3f}x)")


def one_by_one(nets: list[CGNN]) -> Step:
    """The G networks stepped one after another, each with the trainer's Adam."""
    opts = [adam(m.parameters(), 1e-3) for m in nets]

    def step(pts: torch.Tensor, cond: torch.Tensor) -> None:
        for i, (m, opt) in enumerate(zip(nets, opts, strict=True)):
            opt.zero_grad(set_to_none=True)
            loss(*m(pts[i], cond[i])).backward()
            opt.step()
    return step


def stacked_weights(nets: list[CGNN]) -> Params:
    """The G networks' parameters stacked, by name (G, ...), as new leaves."""
    named = [dict(m.named_parameters()) for m in nets]
    return {name: torch.stack([p[name].detach() for p in named]).requires_grad_()
            for name in named[0]}


def as_one(stacked: Params) -> Step:
    """The G networks as one stacked network (:func:`stacked_forward`)."""
    opt = adam(stacked.values(), 1e-3)

    def step(pts: torch.Tensor, cond: torch.Tensor) -> None:
        opt.zero_grad(set_to_none=True)
        loss(*stacked_forward(stacked, CONFIG.k, pts, cond)).backward()
        opt.step()
    return step


def always() -> bool:
    """True (one function object: a compiled graph's guard sees the same one each step)."""
    return True


def no_branch() -> contextlib.AbstractContextManager:
    """The kNN as a traced graph runs it: k + 2 candidates on every row, no branch."""
    return mock.patch.object(knn_module, "fixed_width", always)


def vmapped(nets: list[CGNN]) -> Step:
    """The G networks under ``torch.func.vmap``, the kNN without branches."""
    mapped, buffers = torch.func.stack_module_state(nets)
    opt, base = adam(mapped.values(), 1e-3), CGNN(CONFIG).to("meta")

    def call(p: Params, b: Params, x: torch.Tensor, c: torch.Tensor
             ) -> tuple[torch.Tensor, torch.Tensor]:
        return torch.func.functional_call(base, (p, b), (x, c))

    def step(pts: torch.Tensor, cond: torch.Tensor) -> None:
        opt.zero_grad(set_to_none=True)
        with no_branch():
            out = torch.func.vmap(call)(mapped, buffers, pts, cond)
        loss(*out).backward()
        opt.step()
    return step


def largest_difference(nets: list[CGNN], stacked: Params, pts: torch.Tensor,
                       cond: torch.Tensor) -> float:
    """The largest difference between the stacked network's outputs and each member's own."""
    with torch.no_grad():
        disp, force = stacked_forward(stacked, CONFIG.k, pts, cond)
        own = [m(pts[i], cond[i]) for i, m in enumerate(nets)]
    return max(max(float((d - disp[i]).abs().max()), float((f - force[i]).abs().max()))
               for i, (d, f) in enumerate(own))


def compare(g: int, n: int, steps: int) -> None:
    """Section 3, one row: G networks stacked (bmm), under vmap, and one after another."""
    torch.manual_seed(0)
    nets, gen = [CGNN(CONFIG) for _ in range(g)], torch.Generator().manual_seed(1)
    stacked = stacked_weights(nets)
    print(f" G={g}, N={n}: largest |stacked - own network| "
          f"{largest_difference(nets, stacked, *batches(g, n, gen)):.2g}")
    ways = {"one after another": one_by_one(nets), "stacked (bmm)": as_one(stacked)}
    if BATCH * n * n <= knn_module.BLOCK:        # larger: the kNN's pieces write in place,
        ways["vmap"] = vmapped(nets)           # which vmap refuses
    data: list[tuple[torch.Tensor, torch.Tensor]] = []      # this round's batches

    def next_batches() -> None:
        data[:] = [batches(g, n, gen)]

    ms = timed({w: (lambda fn=fn: fn(*data[0])) for w, fn in ways.items()}, steps,
               between=next_batches)
    seq = ms["one after another"]
    print("  " + "; ".join(f"{w} {v:.1f} ms ({seq / v:.2f}x)" for w, v in ms.items()))


def compiled(n: int, steps: int) -> None:
    """Section 4 (``--compile``): one network's training step under ``torch.compile`` against
    the same step eager, both with the kNN that ranks k + 2 candidates on every row with no
    branch (Dynamo cannot branch on the data), and the trainer's eager step (which branches)
    beside them."""
    torch.manual_seed(0)
    net, gen = CGNN(CONFIG), torch.Generator().manual_seed(1)
    opt, fast = adam(net.parameters(), 1e-3), torch.compile(net, dynamic=False)
    data = [tuple(t[0] for t in batches(1, n, gen))]

    def outputs(model: Callable[..., tuple[torch.Tensor, torch.Tensor]], branch: bool
                ) -> tuple[torch.Tensor, torch.Tensor]:
        with contextlib.nullcontext() if branch else no_branch():
            return model(*data[0])

    def step(model: Callable[..., tuple[torch.Tensor, torch.Tensor]], branch: bool = False
             ) -> None:
        opt.zero_grad(set_to_none=True)
        loss(*outputs(model, branch)).backward()
        opt.step()

    tic = time.perf_counter()
    mine = outputs(fast, False)                      # the training graph, compiled here
    secs = time.perf_counter() - tic
    diff = max(float((a - b).abs().max()) for a, b in zip(mine, outputs(net, False),
                                                          strict=True))
    print(f" compiled in {secs:.0f} s; largest |compiled - eager| {diff:.2g}")

    def next_batch() -> None:
        data[:] = [tuple(t[0] for t in batches(1, n, gen))]

    ms = timed({"eager": partial(step, net), "compiled": partial(step, fast),
                "eager, the trainer's kNN": partial(step, net, True)}, steps,
               between=next_batch)
    print("  " + "; ".join(f"{w} {v:.1f} ms" for w, v in ms.items())
          + f"; compiled's speed-up over eager {ms['eager'] / ms['compiled']:.2f}x")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--groups", type=int, nargs="*", default=[2, 5],
                    help="G of section 3 (none: skip it)")
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--points", type=int, default=26)
    ap.add_argument("--compile", action="store_true",
                    help="also time the network under torch.compile (20-30 s to compile the "
                         "first time, seconds from inductor's cache)")
    a = ap.parse_args()
    torch.set_num_threads(1)
    print(f"training steps of batch {BATCH} x {a.points} points, the recipe's network, one "
          f"thread, torch {torch.__version__}:")
    parts_and_optimizer(a.points, a.steps)
    print("G networks' steps (forward, backward, fused Adam); median ms and the speed-up over "
          "one after another:")
    for g in a.groups:
        compare(g, a.points, a.steps)
    if a.compile:
        print("one network's step, compiled (torch.compile, inductor) against eager:")
        compiled(a.points, a.steps)


if __name__ == "__main__":
    main()

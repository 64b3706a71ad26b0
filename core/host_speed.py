"""How fast is this machine, in one number: seconds for a fixed mix of the work this project
does (small torch training steps, dense and sparse linear algebra, numpy gathers), on one
thread, the median of 3 after a warm-up run.

The method of this project's ``../shared/tools/host_speed.py`` (the shared tools beside the
repository), copied here unchanged so that ``pipeline demo`` can state its time beside the
host's figure without depending on that folder at run time; a figure from either compares
with the other. Run it in a process of its own (``python -m core.host_speed``): it sets one
thread for torch and the BLAS before they load, which must not change the caller's.
"""

from __future__ import annotations

import os
import statistics
import time

LINE = "host_speed: {:.2f} s (median of 3; torch {})"     # the shared tool's output line
ONE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}


def work() -> float:
    """One run of the fixed mix of work (seconds); the shared tool's, line for line."""
    import numpy as np
    import scipy.sparse as sp
    import scipy.sparse.linalg as spl
    import torch

    t = time.perf_counter()
    g = torch.Generator().manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Linear(70, 256), torch.nn.ReLU(), torch.nn.Linear(256, 128),
                              torch.nn.ReLU(), torch.nn.Linear(128, 3))
    opt = torch.optim.Adam(net.parameters(), 1e-3)
    x = torch.randn(32, 256, 70, generator=g)
    y = torch.randn(32, 256, 3, generator=g)
    for _ in range(60):
        opt.zero_grad()
        loss = (net(x) - y).square().mean()
        loss.backward()
        opt.step()
    h = torch.randn(8, 1024, 64, generator=g)
    for _ in range(6):
        d = torch.cdist(h, h)
        d.topk(5, largest=False)
    rng = np.random.default_rng(0)
    for _ in range(10):
        a = rng.standard_normal((400, 400))
        np.linalg.solve(a @ a.T + 400 * np.eye(400), rng.standard_normal(400))
    n = 64
    lap = sp.diags([-1.0, -1.0, 4.0, -1.0, -1.0], [-n, -1, 0, 1, n], shape=(n * n, n * n),
                   format="csc")
    for _ in range(20):
        spl.spsolve(lap, rng.standard_normal(n * n))
    idx = rng.integers(0, 1 << 20, 1 << 22)
    arr = rng.standard_normal(1 << 20)
    for _ in range(10):
        arr[idx].sum()
    return time.perf_counter() - t


def host_speed() -> float:
    """The host's figure (s): the median of 3 runs of :func:`work` after a warm-up, one torch
    thread (call it in a process started with :data:`ONE_THREAD` in its environment)."""
    import torch

    torch.set_num_threads(1)
    work()
    return statistics.median(work() for _ in range(3))


def parse_line(text: str) -> float | None:
    """The figure (s) in a ``host_speed: X s ...`` line of this tool's output, or None."""
    for line in text.splitlines():
        if line.startswith("host_speed:"):
            try:
                return float(line.split()[1])
            except (IndexError, ValueError):
                return None
    return None


if __name__ == "__main__":
    for _name, _value in ONE_THREAD.items():
        os.environ.setdefault(_name, _value)
    import torch as _torch

    print(LINE.format(host_speed(), _torch.__version__))

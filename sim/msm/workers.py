"""Worker processes for the MSM's independent solves (dataset locations, fit sequences)."""

from __future__ import annotations

import multiprocessing
import multiprocessing.pool
import os


def worker_pool(workers: int) -> multiprocessing.pool.Pool:
    """A pool of ``workers`` processes, started fresh (forkserver where there is one): a
    forked copy of a process holding BLAS or torch threads can deadlock."""
    methods = multiprocessing.get_all_start_methods()
    ctx = multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")
    return ctx.Pool(workers)


def default_workers() -> int:
    """Cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1

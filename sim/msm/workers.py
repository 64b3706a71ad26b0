"""Worker processes for the MSM's independent solves (dataset locations, fit sequences)."""

from __future__ import annotations

import multiprocessing
import multiprocessing.pool
import os
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from core.progress import progress

R = TypeVar("R")


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


def run_blocks(work: Callable[[Any], R], jobs: Sequence[Any], workers: int, label: str
               ) -> list[R]:
    """``work`` on each of ``jobs`` in order, in up to ``workers`` processes (here when one),
    with a progress bar named ``label``: a prior's blocks, each drawn from its own seed, so
    the result does not depend on how many."""
    workers = max(1, min(workers, len(jobs)))
    pool = worker_pool(workers) if workers > 1 else None
    try:
        done = pool.imap(work, jobs) if pool else map(work, jobs)
        with progress(done, label, length=len(jobs)) as bar:
            return list(bar)
    finally:
        if pool:
            pool.terminate()
            pool.join()

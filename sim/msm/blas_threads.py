"""Keep the BLAS to one thread while many small factorizations run side by side.

The MSM fast path factors a 3072 x 3072 banded matrix thousands of times; BLAS threads do not
speed up one such factorization, and with one worker process per core they fight for the cores
(the figures: docs/results.md, "The MSM's factorizations and BLAS threads"). The BLAS
reads its thread count when loaded, so once numpy/scipy are imported the handle is its
``set_num_threads`` function, which threadpoolctl finds for every BLAS loaded (OpenBLAS, MKL,
BLIS) on every platform.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

from threadpoolctl import threadpool_limits


@contextlib.contextmanager
def blas_threads(n: int = 1) -> Iterator[None]:
    """Run the block with every loaded BLAS limited to ``n`` threads, then restore."""
    with threadpool_limits(limits=n, user_api="blas"):
        yield

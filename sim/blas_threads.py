"""Keep OpenBLAS to one thread while many small factorizations run side by side.

The MSM fast path factors a 3072 x 3072 banded matrix thousands of times; OpenBLAS threads do
not speed up one such factorization, and with one worker process per core they fight for the
cores (measured: 8 ms single-threaded against 18 ms threaded on a loaded 2-core machine).
OpenBLAS reads its thread count when loaded, so once numpy/scipy are imported the only handle
is its ``*_set_num_threads`` function; this is the small part of threadpoolctl we need.
"""

from __future__ import annotations

import contextlib
import ctypes
from collections.abc import Iterator
from functools import lru_cache
from pathlib import Path

_SETTERS = ("scipy_openblas_set_num_threads", "scipy_openblas_set_num_threads64_",
            "openblas_set_num_threads", "openblas_set_num_threads64_")


@lru_cache(maxsize=1)
def _openblas_libraries() -> tuple[ctypes.CDLL, ...]:
    maps = Path("/proc/self/maps")
    if not maps.exists():
        return ()
    paths = {line.split()[-1] for line in maps.read_text().splitlines()
             if "openblas" in line.lower() and line.split()[-1].startswith("/")}
    libs = []
    for p in sorted(paths):
        with contextlib.suppress(OSError):
            libs.append(ctypes.CDLL(p))
    return tuple(libs)


def _get_set(lib: ctypes.CDLL) -> tuple:
    for name in _SETTERS:
        setter = getattr(lib, name, None)
        if setter is not None:
            getter = getattr(lib, name.replace("set_num", "get_num"), None)
            return getter, setter
    return None, None


@contextlib.contextmanager
def blas_threads(n: int = 1) -> Iterator[None]:
    """Run the block with every loaded OpenBLAS limited to ``n`` threads, then restore."""
    restore = []
    for lib in _openblas_libraries():
        getter, setter = _get_set(lib)
        if setter is None:
            continue
        if getter is not None:
            restore.append((setter, int(getter())))
        setter(ctypes.c_int(n))
    try:
        yield
    finally:
        for setter, old in restore:
            setter(ctypes.c_int(old))

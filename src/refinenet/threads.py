"""Native thread limits (BLAS, OpenMP, numba): they read their thread count once, when first imported, so it must
be set in the environment before anything imports numpy. This module imports nothing that does. Calls that take a
thread count of their own (scipy's k-d tree `workers`, `thread_map`) ask `native_threads`."""

import os
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

T = TypeVar("T")
R = TypeVar("R")

VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


def limit_native_threads(threads: int | str) -> None:
    """Let the native libraries loaded after this call use at most `threads` threads."""
    for variable in VARIABLES:
        os.environ[variable] = str(threads)


def thread_independent_products() -> None:
    """Put MKL in its strict reproducible mode (unless MKL_CBWR is set), for the commands whose results must not
    depend on the thread count: on AVX-512 CPUs torch's float32 products of large K (the output module's 2112
    inputs) otherwise split their sums by thread, and a one-thread tile job disagreed with a two-thread process in
    the last bit. The pipeline's steps run at fixed thread counts and do without it: the mode changes the last bits
    of training's products, and the committed networks were trained in MKL's default mode. MKL reads it at its
    first call, so it holds even where torch was imported first."""
    os.environ.setdefault("MKL_CBWR", "AUTO,STRICT")


def native_threads() -> int:
    """The threads native code may use: the limit `limit_native_threads` set, else every core this process may use.
    scipy's `workers=-1` would take every core of the machine whatever a job was given, and start that many threads
    on every call, however small (a training batch makes dozens of one-point queries)."""
    limit = os.environ.get(VARIABLES[0], "")
    if limit.isdigit() and int(limit) > 0:
        return int(limit)
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def thread_map(fn: Callable[[T], R], items: Iterable[T], threads: int | None = None) -> list[R]:
    """`fn` over `items`, results in order, on `threads` threads (default `native_threads`) when there are several:
    numpy's loops, LAPACK and the nogil numba kernels release the GIL, so the chunks of a cloud run in parallel.
    Each chunk's rows depend on that chunk alone, so results do not depend on the thread count."""
    items = list(items)
    threads = min(native_threads() if threads is None else threads, len(items))
    if threads <= 1:
        return [fn(item) for item in items]
    with ThreadPoolExecutor(max_workers=threads) as pool:
        return list(pool.map(fn, items))

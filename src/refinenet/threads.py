"""Native thread limits (BLAS, OpenMP, numba): they read their thread count once, when first imported, so it must
be set in the environment before anything imports numpy. This module imports nothing that does."""

import os

VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


def limit_native_threads(threads: int | str) -> None:
    """Let the native libraries loaded after this call use at most `threads` threads."""
    for variable in VARIABLES:
        os.environ[variable] = str(threads)

"""Thin entry points, one per step family (`workflow/rules/<family>.smk`): read the params file and the paths a job
works on, call the library,
write outputs atomically. No algorithm code lives here.

BLAS, OpenMP and numba read their thread count once, when first imported, so the `--threads` of the job
(default 1) is put into the environment here, before any stage module imports numpy.
"""

import sys

from refinenet.threads import limit_native_threads

_THREADS = sys.argv[sys.argv.index("--threads") + 1] if "--threads" in sys.argv[:-1] else "1"
if _THREADS.isdigit():
    limit_native_threads(_THREADS)

"""What every stage script shares: the params file, CPU thread limits, malloc thresholds that keep freed memory,
and one-line errors with exit status 2.

A stage script takes the params file, the files it reads and writes, and the identity of its job (a method, a
cluster, a Refine-Net variant), and nothing else: every setting comes from the typed `Params`, so no default lives
in a script.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable

from refinenet import config
from refinenet.allocator import keep_freed_memory
from refinenet.config import Params
from refinenet.errors import RefineNetError

EXIT_BAD_INPUT = 2


def limit_threads(threads: int) -> None:
    """Use at most `threads` cores in torch, so parallel jobs never oversubscribe the machine. (BLAS, OpenMP and
    numba are limited before numpy loads, by the `stages` package.)"""
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(threads)


def run(doc: str, arguments: Callable[[argparse.ArgumentParser], None],
        main: Callable[[Params, argparse.Namespace], None]) -> None:
    """Parse `--params`, `--threads` and the script's own `arguments`, load the params and run `main`; a bad file
    or parameter ends with `error: <what>: <problem>` on one line and exit status 2."""
    parser = argparse.ArgumentParser(description=doc)
    parser.add_argument("--params", default="params.yaml", help="the params file (its active profile applies)")
    parser.add_argument("--threads", type=int, default=1, help="CPU threads this job may use")
    parser.add_argument("--variant", default=config.FULL, help="the Refine-Net variant whose settings apply")
    arguments(parser)
    args = parser.parse_args()
    limit_threads(args.threads)
    keep_freed_memory()
    try:
        main(config.load(args.params, variant=args.variant), args)
    except RefineNetError as err:
        print(f"error: {err}", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)


def normals_job(methods: tuple[str, ...]) -> Callable[[argparse.ArgumentParser], None]:
    """The arguments of a job that estimates one cloud's normals with one of `methods`."""
    def arguments(parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--method", required=True, choices=methods)
        parser.add_argument("--cloud", required=True)
        parser.add_argument("--out", required=True)
    return arguments

"""What every pipeline step's entry point shares: CPU thread limits and one-line errors with a non-zero exit."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from typing import TypeVar

from refinenet.errors import ParamsError, RefineNetError

T = TypeVar("T")

EXIT_BAD_INPUT = 2


def limit_threads(threads: int) -> None:
    """Use at most `threads` cores in torch, so parallel jobs never oversubscribe the machine. (BLAS and OpenMP
    are limited before numpy loads, by the `stages` package.)"""
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(threads)


def run(parser: argparse.ArgumentParser, main: Callable[[argparse.Namespace], None]) -> None:
    """Parse arguments and run `main`; a bad file or parameter ends with `error: <what>: <problem>` and exit 2."""
    parser.add_argument("--threads", type=int, default=1, help="CPU threads this job may use")
    args = parser.parse_args()
    limit_threads(args.threads)
    try:
        main(args)
    except RefineNetError as err:
        print(f"error: {err}", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)


def config_from_json(cls: type[T], text: str, block: str) -> T:
    """A config dataclass from a params block passed as JSON; a bad value is reported under the block's key."""
    try:
        return cls(**json.loads(text))
    except (TypeError, ValueError) as err:
        raise ParamsError(block, str(err)) from None


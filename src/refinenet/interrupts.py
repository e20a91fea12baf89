"""Blocks that a signal must not cut: a handler that finds `is_held()` true defers its signal with `defer`, and
the signal is raised again when the outermost `held` block ends. Python runs signal handlers in the main thread
between bytecodes, so this works where a signal mask would not (any native thread may receive the signal)."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

_depth = 0
_pending: list[int] = []


@contextmanager
def held() -> Iterator[None]:
    """Run the block whole; a deferred signal is raised when it ends. (Only the main thread runs handlers, so
    only its blocks are counted.)"""
    global _depth
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
        if _depth == 0 and _pending:
            signum = _pending[0]
            _pending.clear()
            signal.raise_signal(signum)


def is_held() -> bool:
    return _depth > 0


def defer(signum: int) -> None:
    """Raise `signum` again at the end of the outermost `held` block."""
    _pending.append(signum)

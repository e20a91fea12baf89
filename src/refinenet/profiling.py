"""Where a command's time goes: wall and CPU seconds of its named stages (`refinenet normals --timings`).

A stage costs nothing unless a `recording` is open, so the pipeline's stages carry the same marks for free. A stage
entered again (per tile, stratum or batch) adds to its total. A stage inside another is recorded as `OUTER/INNER`
(MFPS's steps within `mfps`), so the top-level stages sum to the command's time less what lies between them
(start-up, checks). Stages are entered from one thread (the pools run inside them).
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager

_totals: dict[str, dict[str, float]] | None = None
_open: list[str] = []


@contextmanager
def stage(name: str) -> Iterator[None]:
    """Count the block's wall and CPU seconds (every thread of the process) to `name`, if recording."""
    if _totals is None:
        yield
        return
    key = "/".join([*_open, name])
    _open.append(name)
    wall, cpu = time.perf_counter(), time.process_time()
    try:
        yield
    finally:
        _open.pop()
        total = _totals.setdefault(key, {"wall_s": 0.0, "cpu_s": 0.0, "calls": 0})
        total["wall_s"] += time.perf_counter() - wall
        total["cpu_s"] += time.process_time() - cpu
        total["calls"] += 1


@contextmanager
def recording() -> Iterator[dict[str, dict[str, float]]]:
    """Record the stages run in the block; yields {stage: {wall_s, cpu_s, calls}}, in the order first entered."""
    global _totals, _open
    previous, _totals = (_totals, _open), {}
    _open = []
    try:
        yield _totals
    finally:
        _totals, _open = previous

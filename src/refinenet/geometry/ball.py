"""Uniform random subsets of fixed-radius balls (the paper's point patches, docs/algorithm.md §6), on a hashed grid
compiled with numba.

Why: the training loader builds a batch's patches on every step, and on a GPU that loader, not the network, bounds
the training speed (benchmarks/results/loader.md). A dual-tree ball query followed by a sort per batch spent
about 90 ms on 512 balls of ~400 points; here each ball visits the 27 grid cells around its centre (cells as wide
as the radius, looked up by binary search in the sorted cell keys, so memory stays O(N) at any extent) and keeps
a uniform subset by reservoir sampling in one pass.

Each ball draws from its own counter-based generator (splitmix64 of the batch seed and the ball's row), so a
subset depends only on the seed and the row, not on the order in which balls are visited.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

#: Cells per axis at most: the int64 cell keys of a cloud of any extent fit (cells grow instead; the search stays
#: the 27 cells around a centre, which is exact while a cell is at least as wide as the radius).
MAX_CELLS_PER_AXIS = 1 << 20


@dataclass(frozen=True)
class BallGrid:
    """Points sorted by the key of their cell, the cells at least as wide as `radius`."""

    points: np.ndarray  # (N, 3) float64, sorted by cell key
    order: np.ndarray  # (N,) int64: original index of each sorted point
    rank: np.ndarray  # (N,) int64: sorted position of each original point (the inverse of order)
    keys: np.ndarray  # (N,) int64 sorted cell keys
    dims: np.ndarray  # (3,) int64 cells per axis
    origin: np.ndarray  # (3,) float64
    cell: float
    radius: float


def ball_grid(points: np.ndarray, radius: float) -> BallGrid:
    """The grid of `points` for balls of `radius` (built once per cloud; a batch's query is then milliseconds)."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    if not radius > 0:
        raise ValueError(f"ball radius must be positive, got {radius}")
    origin = points.min(axis=0)
    extent = points.max(axis=0) - origin
    cell = max(float(radius), float(extent.max()) / (MAX_CELLS_PER_AXIS - 1))
    dims = (extent / cell).astype(np.int64) + 1
    keys = _keys(((points - origin) / cell).astype(np.int64), dims)
    order = np.argsort(keys, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return BallGrid(points[order], order, rank, keys[order], dims, origin, cell, float(radius))


def random_ball_subsets(grid: BallGrid, centres: np.ndarray, max_points: int, seed: int) -> np.ndarray:
    """(M, max_points) indices: for each centre (an index into the grid's cloud), a uniform random subset of at
    most `max_points` of the points within `radius` (distance <= radius), padded with the centre's own index."""
    centres = np.ascontiguousarray(centres, dtype=np.int64)
    out = np.empty((len(centres), max_points), dtype=np.int64)
    _subsets(grid.points, grid.order, grid.keys, grid.dims, grid.origin, grid.cell, grid.radius ** 2,
             grid.rank[centres], centres, np.uint64(seed), out)
    return out


def _keys(ijk: np.ndarray, dims: np.ndarray) -> np.ndarray:
    return (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]


@njit(cache=True)
def _next(state):
    """splitmix64: the next (state, value) of a counter-based generator."""
    state = state + np.uint64(0x9E3779B97F4A7C15)
    z = state
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return state, z ^ (z >> np.uint64(31))


@njit(cache=True)
def _subsets(points, order, keys, dims, origin, cell, r2, sorted_centres, centres, seed, out):
    m = out.shape[1]
    for row in range(len(centres)):
        q = points[sorted_centres[row]]
        cx, cy, cz = int((q[0] - origin[0]) / cell), int((q[1] - origin[1]) / cell), int((q[2] - origin[2]) / cell)
        state = seed ^ (np.uint64(row) * np.uint64(0xD1B54A32D192ED03))
        count = 0
        for i in range(max(cx - 1, 0), min(cx + 1, dims[0] - 1) + 1):
            for j in range(max(cy - 1, 0), min(cy + 1, dims[1] - 1) + 1):
                first = (i * dims[1] + j) * dims[2]
                lo = np.searchsorted(keys, first + max(cz - 1, 0))
                hi = np.searchsorted(keys, first + min(cz + 1, dims[2] - 1), side="right")
                for p in range(lo, hi):
                    d0, d1, d2 = points[p, 0] - q[0], points[p, 1] - q[1], points[p, 2] - q[2]
                    if d0 * d0 + d1 * d1 + d2 * d2 > r2:
                        continue
                    if count < m:
                        out[row, count] = order[p]
                    else:  # reservoir sampling: the (count+1)-th member replaces a kept one with chance m/(count+1)
                        state, value = _next(state)
                        slot = value % np.uint64(count + 1)
                        if slot < m:
                            out[row, slot] = order[p]
                    count += 1
        for s in range(count, m):
            out[row, s] = centres[row]

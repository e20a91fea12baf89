"""Exact k nearest neighbours of a point cloud on a uniform grid, compiled with numba.

Why: for k around 100, scipy's cKDTree spends most of a query maintaining its sorted result heap, and ends up
slower than Open3D's `estimate_normals` (benchmarks/results/pca.md). On a grid whose cells are a fraction of the
k-th neighbour distance, each query only looks at a small block of cells; its candidates are selected in
linear time and only the k winners are sorted.

Exactness: a query's answer is kept only when its k-th distance is no larger than the distance from the query
to the boundary of the searched block, so no point outside the block can be closer. Every other query (sparse
regions, outliers, an over-full block) goes to the k-d tree, which stays the reference implementation.
Tied distances may come back in a different order than the tree's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from numba import njit, prange
from scipy.spatial import cKDTree

from refinenet.threads import native_threads

# Prefer OpenMP: the TBB layer warns about the libtbb that ships beside open3d and is skipped anyway.
numba.config.THREADING_LAYER_PRIORITY = ["omp", "tbb", "workqueue"]

#: Cells per k-th neighbour distance. The searched block is (2 RINGS + 1)^3 cells; more, smaller cells hug the
#: neighbourhood ball more tightly (measured on a 100k-point surface at k = 100: 400 candidates per query with
#: 1 ring, 280 with 2, 250 with 3) but cost more empty-cell lookups.
RINGS = 2
#: Cell size = this quantile of the k-th neighbour distance over a sample of points, divided by RINGS; the
#: queries above it (about 1 - quantile of them, plus outliers) fall back to the k-d tree. Measured on 100k
#: points at k = 100: 0.97 sends 1% of the queries to the tree and beats 0.9 (3%) and 1.0 (larger blocks).
RADIUS_QUANTILE = 0.97
#: No grid when the k-th neighbour distance at that quantile is more than this many times the one at the
#: opposite quantile (1 - RADIUS_QUANTILE).
MAX_DENSITY_SPREAD = 3.0
#: Neighbours probed at least, to size the cells for small k.
MIN_PROBE = 16
#: Points sampled to estimate the k-th neighbour distance.
SAMPLE = 512
#: Quantiles of the sampled k-th neighbour distance that bound the band where each query's k-th is sought first.
BAND = (0.02, 0.98)
#: The band is narrowed until it holds about this many candidates.
BAND_TARGET = 8
#: A query whose block holds more candidates than this many times max(k, MIN_PROBE) goes to the tree instead
#: (dense clumps, duplicate points): it bounds the work of one query.
MAX_CANDIDATES_PER_K = 32
#: The grid never has more cells than this many per point (a far outlier would otherwise blow the grid up);
#: cells grow instead, which keeps the answers exact.
MAX_CELLS_PER_POINT = 8


@dataclass(frozen=True)
class Grid:
    """Points sorted by cell; the points of cell c are `points[starts[c]:starts[c + 1]]`, `order` maps back."""

    cloud: np.ndarray  # (N, 3) float64, the points as given
    points: np.ndarray  # (N, 3) float64, sorted by cell
    order: np.ndarray  # (N,) int64: original index of each sorted point
    starts: np.ndarray  # (cells + 1,) int64
    dims: np.ndarray  # (3,) int64 cells per axis
    origin: np.ndarray  # (3,) float64
    cell: float
    band: np.ndarray  # (2,) float64: squared distances where the k-th neighbour usually lies
    cap: int  # most candidates one query may scan; fuller blocks go to the tree


def _cell_ids(points: np.ndarray, origin: np.ndarray, cell: float, dims: np.ndarray) -> np.ndarray:
    """Linear cell index of each point; points beyond the grid go to its border cells, which keeps every
    block margin a true lower bound on the distance to the points outside the block."""
    ijk = np.clip(((points - origin) / cell).astype(np.int64), 0, dims - 1)
    return (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]


def build_grid(points: np.ndarray, k: int, tree: cKDTree) -> Grid | None:
    """A grid sized for kNN_k queries on `points`, or None where one would not pay.

    The cell size comes from the k-th neighbour distance of a sample of points. A grid does not pay when
    that distance varies too much over the cloud (clusters of very different density: the queries of one
    kind or the other would all fall back to the tree) or is zero (duplicate points).
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    n = len(points)
    sample = points[np.random.default_rng(0).choice(n, min(n, SAMPLE), replace=False)]
    # the spread of the k-th distance is only a density measure for k well above 1 (the 1st is the point)
    probe = min(max(k, MIN_PROBE), n)
    dist = tree.query(sample, k=probe, workers=native_threads())[0]
    low, radius = np.quantile(dist[:, -1], [1 - RADIUS_QUANTILE, RADIUS_QUANTILE])
    if not (low > 0 and radius <= MAX_DENSITY_SPREAD * low and np.all(np.isfinite(sample))):
        return None
    cell = radius / RINGS
    # bounds from the bulk of the sample, so that a few far outliers do not stretch the grid
    lo, hi = np.quantile(sample, [0.01, 0.99], axis=0)
    pad = 0.05 * (hi - lo) + cell
    lo, hi = lo - pad, hi + pad
    cells = np.prod((hi - lo) / cell + 1)
    if cells > MAX_CELLS_PER_POINT * n:
        cell *= (cells / (MAX_CELLS_PER_POINT * n)) ** (1 / 3)
    dims = ((hi - lo) / cell).astype(np.int64) + 1
    ids = _cell_ids(points, lo, cell, dims)
    order = np.argsort(ids, kind="stable")
    starts = np.searchsorted(ids[order], np.arange(int(dims.prod()) + 1))
    return Grid(points, points[order], order, starts, dims, lo, float(cell), np.quantile(dist[:, k - 1], BAND) ** 2,
                MAX_CANDIDATES_PER_K * probe)


def grid_knn(grid: Grid, queries: np.ndarray, k: int, with_distances: bool = True,
             index_dtype: type = np.int64) -> tuple[np.ndarray | None, np.ndarray, np.ndarray]:
    """Distances (or None), indices (closest first) and a `done` mask: rows not done are left for the tree.

    `index_dtype=np.int32` halves the memory of large neighbour lists (MFPS keeps N x 225 of them).
    """
    queries = np.ascontiguousarray(queries, dtype=np.float64)
    m = len(queries)
    dist = np.empty((m, k) if with_distances else (0, k))
    idx = np.empty((m, k), dtype=index_dtype)
    done = np.zeros(m, dtype=np.bool_)
    _kernel(*_kernel_args(grid, queries), k, RINGS, grid.cap, grid.band, dist, idx, np.empty((0, 3, 3)), done)
    return (dist if with_distances else None), idx, done


def grid_covariances(grid: Grid, k: int, block: slice = slice(None)) -> tuple[np.ndarray, np.ndarray]:
    """Covariances (M, 3, 3), divided by k, of kNN_k of the grid's points `grid.order[block]` (a block in cell
    order is a compact piece of the cloud), without storing the lists, and the `done` mask (rows not done are
    left for the tree)."""
    queries = grid.points[block]
    covs = np.empty((len(queries), 3, 3))
    done = np.zeros(len(queries), dtype=np.bool_)
    _kernel(*_kernel_args(grid, queries), k, RINGS, grid.cap, grid.band, np.empty((0, k)),
            np.empty((0, k), dtype=np.int64), covs, done)
    return covs, done


def _kernel_args(grid: Grid, queries: np.ndarray) -> tuple:
    """Grid arrays plus the queries and their visiting order (by cell, so neighbouring queries share cache)."""
    if queries is grid.cloud:
        visit = grid.order
    else:
        visit = np.argsort(_cell_ids(queries, grid.origin, grid.cell, grid.dims), kind="stable")
    return grid.points, grid.order, grid.starts, grid.dims, grid.origin, grid.cell, queries, visit


@njit(cache=True)
def _candidates(sp, starts, dims, origin, cell, q, rings, cap):
    """Squared distances from q to the points of its block and their sorted positions, plus the block margin.

    Returns empty arrays when the block holds more than `cap` points. The margin is the distance from q to
    the nearest block face that has grid beyond it (infinite if the block covers the whole grid).
    """
    c = np.empty(3, np.int64)
    lo = np.empty(3, np.int64)
    hi = np.empty(3, np.int64)
    margin = np.inf
    for a in range(3):
        c[a] = min(max(int((q[a] - origin[a]) / cell), 0), dims[a] - 1)
        lo[a] = max(c[a] - rings, 0)
        hi[a] = min(c[a] + rings + 1, dims[a])
        if lo[a] > 0:
            margin = min(margin, q[a] - (origin[a] + lo[a] * cell))
        if hi[a] < dims[a]:
            margin = min(margin, origin[a] + hi[a] * cell - q[a])
    count = 0
    for ix in range(lo[0], hi[0]):
        for iy in range(lo[1], hi[1]):
            base = (ix * dims[1] + iy) * dims[2]
            count += starts[base + hi[2]] - starts[base + lo[2]]
    if count > cap:
        return np.empty(0), np.empty(0, np.int64), margin
    d = np.empty(count)
    j = np.empty(count, np.int64)
    n = 0
    for ix in range(lo[0], hi[0]):
        for iy in range(lo[1], hi[1]):
            base = (ix * dims[1] + iy) * dims[2]
            for s in range(starts[base + lo[2]], starts[base + hi[2]]):
                dx = sp[s, 0] - q[0]
                dy = sp[s, 1] - q[1]
                dz = sp[s, 2] - q[2]
                d[n] = dx * dx + dy * dy + dz * dz
                j[n] = s
                n += 1
    return d, j, margin


@njit(cache=True)
def _quickselect(v, t):
    """The value of rank t (0-based) of v, which is reordered (Hoare partition, median-of-three pivot)."""
    lo, hi = 0, len(v) - 1
    while lo < hi:
        a, b, c = v[lo], v[(lo + hi) >> 1], v[hi]
        pivot = max(min(a, b), min(max(a, b), c))
        left, right = lo, hi
        while left <= right:
            while v[left] < pivot:
                left += 1
            while v[right] > pivot:
                right -= 1
            if left <= right:
                v[left], v[right] = v[right], v[left]
                left += 1
                right -= 1
        if t <= right:
            hi = right
        elif t >= left:
            lo = left
        else:
            break
    return v[t]


@njit(cache=True)
def _count(d, lower, upper):
    """How many values of d lie below `lower`, and how many in [lower, upper); branch-free."""
    below = 0
    inside = 0
    for s in range(len(d)):
        below += d[s] < lower
        inside += (d[s] >= lower) & (d[s] < upper)
    return below, inside


@njit(cache=True)
def _kth_smallest(d, k, lower, upper):
    """The k-th smallest of d, expected in [lower, upper).

    Why not a plain quickselect: over a few hundred distances it is dominated by mispredicted branches.
    Branch-free counting passes narrow the band that holds the k-th instead: on a surface the squared
    neighbour distance grows about linearly with rank, so interpolating inside the band predicts where the
    k-th lies, and a band of a few values around the prediction is checked by counting. Only the final band
    is selected; when the guess misses, the whole array is.
    """
    below, inside = _count(d, lower, upper)
    if not below < k <= below + inside:
        return _quickselect(d.copy(), k - 1)
    for _ in range(3):
        if inside <= BAND_TARGET:
            break
        guess = lower + (upper - lower) * (k - below - 0.5) / inside
        half = (upper - lower) * 0.5 * BAND_TARGET / inside
        narrow_lower, narrow_upper = max(lower, guess - half), min(upper, guess + half)
        narrow_below, narrow_inside = _count(d, narrow_lower, narrow_upper)
        if not narrow_below < k <= narrow_below + narrow_inside:
            break
        lower, upper, below, inside = narrow_lower, narrow_upper, narrow_below, narrow_inside
    band = np.empty(inside + 1)
    m = 0
    for s in range(len(d)):
        band[m] = d[s]
        m += (d[s] >= lower) & (d[s] < upper)
    return _quickselect(band[:inside], k - below - 1)


@njit(cache=True)
def _nearest(d, k, band, margin):
    """1.0 for the k nearest candidates, 0.0 for the others: every candidate below the k-th distance, then as
    many at it as are needed. Empty when the k nearest of the block are not provably those of the cloud."""
    if len(d) < k:
        return np.empty(0)
    tau = _kth_smallest(d, k, band[0], band[1])
    if tau > margin * margin:
        return np.empty(0)
    ties = k - _count(d, tau, tau)[0]
    w = np.empty(len(d))
    for s in range(len(d)):
        w[s] = 1.0 if d[s] < tau else 0.0
        if ties > 0 and d[s] == tau:
            w[s] = 1.0
            ties -= 1
    return w


@njit(parallel=True, cache=True)
def _kernel(sp, order, starts, dims, origin, cell, queries, visit, k, rings, cap, band, dist, idx, covs, done):
    """kNN lists (into dist, unless it has no rows, and idx) or, when covs has rows, covariances instead."""
    for t in prange(len(visit)):
        q = visit[t]
        d, j, margin = _candidates(sp, starts, dims, origin, cell, queries[q], rings, cap)
        w = _nearest(d, k, band, margin)
        if len(w) == 0:
            continue
        if covs.shape[0] > 0:
            _covariance(sp, j, w, queries[q], k, covs[q])
        else:
            take = np.flatnonzero(w)
            take = take[np.argsort(d[take])]
            for s in range(k):
                idx[q, s] = order[j[take[s]]]
            if dist.shape[0] > 0:
                for s in range(k):
                    dist[q, s] = np.sqrt(d[take[s]])
        done[q] = True


@njit(cache=True)
def _covariance(sp, j, w, q, k, out):
    """Covariance (divided by k) of the candidates of weight 1, accumulated about the query point q (close to
    the centroid, so the one-pass formula stays accurate); 0/1 weights rather than a mispredictable branch."""
    sx = sy = sz = sxx = sxy = sxz = syy = syz = szz = 0.0
    for s in range(len(j)):
        x = (sp[j[s], 0] - q[0]) * w[s]
        y = (sp[j[s], 1] - q[1]) * w[s]
        z = (sp[j[s], 2] - q[2]) * w[s]
        sx += x
        sy += y
        sz += z
        sxx += x * x
        sxy += x * y
        sxz += x * z
        syy += y * y
        syz += y * z
        szz += z * z
    mx, my, mz = sx / k, sy / k, sz / k
    out[0, 0] = sxx / k - mx * mx
    out[1, 1] = syy / k - my * my
    out[2, 2] = szz / k - mz * mz
    out[0, 1] = out[1, 0] = sxy / k - mx * my
    out[0, 2] = out[2, 0] = sxz / k - mx * mz
    out[1, 2] = out[2, 1] = syz / k - my * mz

"""Nearest-neighbour queries and batched local covariances, shared by every geometric stage.

kNN lists include the query point itself and come back closest first, so `idx[:, 0]` is the point
(docs/algorithm.md, notation). Work is chunked so that N x k x 3 gathers never exceed a bounded size.
Large query sets go through the exact uniform-grid kernels of `grid_knn`, which hand back to the k-d tree
every query they cannot prove; small ones go straight to the tree, as a grid costs a sort of the cloud.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
from scipy.spatial import cKDTree

from refinenet.geometry.grid_knn import Grid, build_grid, grid_covariances, grid_knn
from refinenet.threads import native_threads

#: Neighbour entries (rows x k) gathered per chunk: small enough that the gathered arrays stay in cache
#: (measured: 100k x 100 covariances take 0.1 s in chunks of 1M entries, 0.65 s in chunks of 8M).
CHUNK_ELEMENTS = 1_000_000
#: Points per block of `knn_blocks` and `pca_normals`, which hold the lists or covariances of one block at a time.
BLOCK_POINTS = 1 << 18
#: Query sets at least this large, and at least a quarter of the cloud, go through the grid.
GRID_MIN_QUERIES = 10_000


def build_tree(points: np.ndarray) -> cKDTree:
    """A k-d tree over the cloud; build once and reuse it for every query on the same points."""
    return cKDTree(np.asarray(points, dtype=np.float64))


def knn(points: np.ndarray, k: int, tree: cKDTree | None = None, query: np.ndarray | None = None,
        with_distances: bool = True, index_dtype: type = np.int64) -> tuple[np.ndarray | None, np.ndarray]:
    """Distances and indices of the k nearest points (self included), closest first.

    Returns `(dist, idx)` of shape (M, k), M = len(query) or len(points); `dist` is None when not asked for.
    `index_dtype=np.int32` halves the memory of large neighbour lists (MFPS keeps N x 225 of them).
    """
    points = _cloud_for(points, k)
    tree = tree if tree is not None else build_tree(points)
    q = points if query is None else np.asarray(query, dtype=np.float64)
    grid = _grid_for(points, k, tree, len(q))
    if grid is None:
        dist = np.empty((len(q), k)) if with_distances else None
        idx = np.empty((len(q), k), dtype=index_dtype)
        rows = tree.indices if query is None else np.arange(len(q))
    else:
        dist, idx, done = grid_knn(grid, q, k, with_distances, index_dtype)
        rows = np.flatnonzero(~done)
    _tree_knn(tree, q, k, rows, dist, idx)
    return dist, idx


def neighbour_lists(points: np.ndarray, k: int) -> np.ndarray:
    """kNN_k of every point as int32 (closest first, self included), without distances, which halves the memory:
    the lists a chain of stages shares, each taking the first k' <= k columns (`first_neighbours`)."""
    return knn(points, k, with_distances=False, index_dtype=np.int32)[1]


def first_neighbours(neighbours: np.ndarray, k: int) -> np.ndarray:
    """The first k columns of shared kNN lists: the kNN_k lists themselves (ties at the k-th aside)."""
    if neighbours.shape[1] < k:
        raise ValueError(f"kNN lists of {neighbours.shape[1]} neighbours, {k} needed")
    return neighbours[:, :k]


def nearest_at(points: np.ndarray, k: int, index: np.ndarray, tree: cKDTree | None = None,
               neighbours: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The distance to the k-th nearest neighbour (M,) and kNN_k (M, k) of points[index]: from `neighbours`, their
    shared lists (the distance recomputed as `knn` gives it, to the bit), else from a query."""
    if neighbours is None:
        dist, idx = knn(points, k, tree=tree, query=points[index])
        return dist[:, -1], idx
    idx = first_neighbours(neighbours, k)
    return np.sqrt(np.square(points[idx[:, -1]] - points[index]).sum(axis=1)), idx


def _grid_for(points: np.ndarray, k: int, tree: cKDTree, n_queries: int) -> Grid | None:
    """A grid for kNN_k on `points` when `n_queries` queries repay its sort of the cloud, else None."""
    return build_grid(points, k, tree) if n_queries >= max(GRID_MIN_QUERIES, len(points) // 4) else None


def _cloud_for(points: np.ndarray, k: int) -> np.ndarray:
    points = np.asarray(points, dtype=np.float64)
    if k > len(points):
        raise ValueError(f"k = {k} neighbours requested but the cloud has only {len(points)} points")
    return points


def _tree_knn(tree: cKDTree, query: np.ndarray, k: int, rows: np.ndarray, dist: np.ndarray | None,
              idx: np.ndarray) -> None:
    """Fill `dist[rows]` (unless None) and `idx[rows]` with the k-d tree's answer for `query[rows]`, in chunks
    that bound the tree's temporaries.

    Rows in the tree's leaf order (a self-query) make neighbouring queries walk the same nodes, which halves
    the query time on a 1M-point cloud stored in random order.
    """
    for sl in chunks(len(rows), k):
        d, i = tree.query(query[rows[sl]], k=k, workers=native_threads())
        idx[rows[sl]] = i.reshape(-1, k)
        if dist is not None:
            dist[rows[sl]] = d.reshape(-1, k)


def knn_blocks(points: np.ndarray, k: int, index_dtype: type = np.int32) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """The kNN_k lists of every point (as `knn`'s, without distances) a block at a time: (rows, their lists), so
    that a large cloud's lists are never all held (at 10M points and k = 32, 1.3 GB)."""
    for tree, grid, block, rows in _blocks(points, k):
        if grid is None:
            idx, rest = np.empty((len(rows), k), dtype=index_dtype), np.arange(len(rows))
        else:
            _, idx, done = grid_knn(grid, grid.points[block], k, False, index_dtype)
            rest = np.flatnonzero(~done)
        _tree_knn(tree, tree.data[rows], k, rest, None, idx)
        yield rows, idx


def pca_normals(points: np.ndarray, k: int) -> np.ndarray:
    """Normal = eigenvector of the smallest eigenvalue of the k-neighbourhood covariance (Hoppe et al. 1992), unit
    and unoriented, of every point; a block at a time, so that neither the lists nor all the N x 3 x 3
    covariances are held (at 10M points 1.2 and 0.7 GB)."""
    normals = np.empty((len(points), 3))
    for tree, grid, block, rows in _blocks(points, k):
        if grid is None:
            covs, done = np.empty((len(rows), 3, 3)), np.zeros(len(rows), dtype=bool)
        else:
            covs, done = grid_covariances(grid, k, block)
        rest = np.flatnonzero(~done)
        for sl in chunks(len(rest), k):
            idx = tree.query(tree.data[rows[rest[sl]]], k=k, workers=native_threads())[1].reshape(-1, k)
            covs[rest[sl]] = covariances(tree.data, idx)[1]
        normals[rows] = smallest_eigenvectors(covs)[1]
    return normals


def _blocks(points: np.ndarray, k: int) -> Iterator[tuple[cKDTree, Grid | None, slice, np.ndarray]]:
    """The cloud's tree and grid for kNN_k queries, and its blocks of BLOCK_POINTS (`block` in the grid's cell
    order, else the tree's leaf order, so that each is a compact piece of the cloud, and the `rows` it holds)."""
    points = _cloud_for(points, k)
    tree = build_tree(points)
    grid = _grid_for(points, k, tree, len(points))
    order = tree.indices if grid is None else grid.order
    for block in chunks(len(points), 1, BLOCK_POINTS):
        yield tree, grid, block, order[block]


def chunks(n: int, k: int, max_elements: int = CHUNK_ELEMENTS) -> Iterator[slice]:
    """Slices over n rows so that each chunk gathers at most `max_elements` neighbour entries."""
    step = max(1, max_elements // max(k, 1))
    for start in range(0, n, step):
        yield slice(start, min(n, start + step))


def covariances(points: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centroids (M, 3) and covariances (M, 3, 3) of the neighbourhoods `points[idx]`, divided by k.

    Coordinates are gathered one axis at a time (three contiguous 1-D gathers are several times faster
    than one N x k x 3 gather) and taken relative to the first neighbour, the query point, which keeps the
    one-pass formula accurate for clouds far from the origin.
    """
    axes = [np.ascontiguousarray(points[:, a], dtype=np.float64) for a in range(3)]
    m, k = idx.shape
    centroids = np.empty((m, 3))
    covs = np.empty((m, 3, 3))
    for sl in chunks(m, k):
        rows = idx[sl]
        local = [ax[rows] - ax[rows[:, :1]] for ax in axes]
        mean = [c.mean(axis=1) for c in local]
        for a in range(3):
            centroids[sl, a] = mean[a] + axes[a][rows[:, 0]]
            for b in range(a, 3):
                cov = np.einsum("ij,ij->i", local[a], local[b]) / k - mean[a] * mean[b]
                covs[sl, a, b] = covs[sl, b, a] = cov
    return centroids, covs


def smallest_eigenvectors(covs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (ascending, M x 3) and the eigenvector of the smallest one (M x 3) of symmetric 3x3 matrices.

    Solved in chunks, so that the M x 3 x 3 eigenvectors of which one column is kept are never all held at once
    (about 0.7 GB at 10M points); each matrix's solution is the same as in one call."""
    dtype = np.promote_types(covs.dtype, np.float32)  # eigh's: float32 stays float32
    w, v = np.empty(covs.shape[:2], dtype), np.empty(covs.shape[:2], dtype)
    for sl in chunks(len(covs), 9):
        w[sl], vectors = np.linalg.eigh(covs[sl])
        v[sl] = vectors[:, :, 0]
    return w, v

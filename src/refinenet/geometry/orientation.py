"""Consistent orientation of unoriented normals: the refined normals are sign-free (the paper evaluates the
unoriented angle), while users reconstructing surfaces need them to point outwards.

* `orient_mst`: propagation over a minimum spanning tree of the k-NN graph (Hoppe et al. 1992, the method behind
  Open3D's `orient_normals_consistent_tangent_plane`). Edge cost 1 - |n_i . n_j| makes the tree follow nearly
  parallel neighbours, so a flip decision is rarely taken across a sharp edge or between close sheets. In each
  connected part the walk starts at the point of largest z, whose normal on a closed surface points up (outwards).
  The walk runs on PCA normals, which turn gradually around an edge, and each given normal takes the sign of its
  point's: sharp normals are a poor field to walk on, since across an edge neighbours differ by up to 90 degrees or
  more and the sign test there is a coin toss (MFPS's normals of a 10k-point fandisk came out 50% outward when
  walked on directly, 99.7% this way). The PCA takes more neighbours (GUIDE_K) than the graph links: on the graph's
  own 12 the field is as noisy as the cloud is dense, and a 1M-point fandisk with 0.1% noise came out 98.0%
  outward from its exact normals, 0.5% noise 49%; with 30, 99.97% and 90% (studies/results/orientation.md).
  Across a wedge sharper than a right angle (a cone's rim) the PCA field turns the wrong way whatever its size,
  and the face beyond can come out flipped.
* `orient_viewpoint`: every normal towards a sensor position, for scans with a known origin.
"""

from __future__ import annotations

import numba
import numpy as np

from refinenet.geometry.neighbors import knn, pca_normals

#: Neighbours per point in the propagation graph.
MST_K = 12
#: Neighbours of the PCA normals the walk runs on.
GUIDE_K = 30


def orient_viewpoint(points: np.ndarray, normals: np.ndarray, viewpoint: np.ndarray) -> np.ndarray:
    """Normals flipped to face `viewpoint` (3,): n . (viewpoint - p) >= 0."""
    facing = np.einsum("ij,ij->i", normals, np.asarray(viewpoint, dtype=np.float64) - points) < 0
    return np.where(facing[:, None], -normals, normals)


def orient_mst(points: np.ndarray, normals: np.ndarray, k: int = MST_K) -> np.ndarray:
    """Normals made consistent along a minimum spanning tree of the k-NN graph, each part's root pointing up; the
    walk is on the PCA normals of GUIDE_K neighbours, whose signs the given normals take."""
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    n = len(points)
    guide = pca_normals(points, min(GUIDE_K + 1, n))
    neighbours = knn(points, min(k + 1, n), with_distances=False, index_dtype=np.int32)[1]
    # Roots in falling height (ties: the lower index), so that each part's walk starts at its highest point.
    roots = np.argsort(-points[:, 2], kind="stable")
    _orient_along_mst(guide, neighbours, *_reverse_lists(neighbours), roots)
    return np.where((np.einsum("ij,ij->i", normals, guide) < 0)[:, None], -normals, normals)


@numba.njit(cache=True)
def _reverse_lists(neighbours: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The k-NN graph's reverse edges as CSR (`starts`, `sources`): the points whose lists hold each point (its
    own first column left out), so that the walk sees every edge from both ends, as in an undirected graph."""
    n = len(neighbours)
    starts = np.zeros(n + 1, dtype=np.int64)
    for i in range(n):
        for j in neighbours[i, 1:]:
            starts[j + 1] += 1
    for i in range(n):
        starts[i + 1] += starts[i]
    fill = starts[:-1].copy()
    sources = np.empty(starts[n], dtype=np.int32)
    for i in range(n):
        for j in neighbours[i, 1:]:
            sources[fill[j]] = i
            fill[j] += 1
    return starts, sources


@numba.njit(cache=True)
def _orient_along_mst(normals: np.ndarray, neighbours: np.ndarray, starts: np.ndarray, sources: np.ndarray,
                      roots: np.ndarray) -> None:
    """Prim's minimum spanning forest of the graph of edge cost 1 - |n_i . n_j|, flipping each normal, as its
    point joins the tree, to agree with the one it joins through; each part's first point (in `roots` order)
    turns upwards. The costs are computed as they are met and the heap holds one entry per point, so that
    besides the graph's lists (about 1 GB at 10M points) the walk needs a few bytes per point."""
    n = len(normals)
    key = np.full(n, np.inf)
    parent = np.full(n, -1, dtype=np.int32)  # int32 as the lists are
    joined = np.zeros(n, dtype=np.bool_)
    heap = np.empty(n, dtype=np.int32)  # a binary min-heap of points by key; place[i]: i's slot, -1 outside
    place = np.full(n, -1, dtype=np.int32)
    for root in roots:
        if joined[root]:
            continue
        if normals[root, 2] < 0:
            normals[root] = -normals[root]
        heap[0], place[root], size = root, 0, 1
        while size:
            i = heap[0]
            place[i] = -1
            size -= 1
            if size:
                heap[0] = heap[size]
                _sift_down(heap, place, key, 0, size)
            joined[i] = True
            j = parent[i]
            if j >= 0 and _dot(normals, i, j) < 0:
                normals[i] = -normals[i]
            for v in neighbours[i, 1:]:
                size = _relax(normals, key, parent, joined, heap, place, size, i, v)
            for v in sources[starts[i]:starts[i + 1]]:
                size = _relax(normals, key, parent, joined, heap, place, size, i, v)


@numba.njit(cache=True)
def _dot(normals: np.ndarray, i: int, j: int) -> float:
    return normals[i, 0] * normals[j, 0] + normals[i, 1] * normals[j, 1] + normals[i, 2] * normals[j, 2]


@numba.njit(cache=True)
def _relax(normals: np.ndarray, key: np.ndarray, parent: np.ndarray, joined: np.ndarray, heap: np.ndarray,
           place: np.ndarray, size: int, i: int, v: int) -> int:
    """Offer point v the edge from the tree's point i; returns the heap's new size."""
    if joined[v]:
        return size
    cost = 1.0 - abs(_dot(normals, i, v))
    if cost < key[v]:
        key[v], parent[v] = cost, i
        if place[v] < 0:
            heap[size], place[v] = v, size
            size += 1
        _sift_up(heap, place, key, place[v])
    return size


@numba.njit(cache=True)
def _sift_up(heap: np.ndarray, place: np.ndarray, key: np.ndarray, slot: int) -> None:
    item = heap[slot]
    while slot > 0:
        up = (slot - 1) >> 1
        if key[heap[up]] <= key[item]:
            break
        heap[slot] = heap[up]
        place[heap[slot]] = slot
        slot = up
    heap[slot], place[item] = item, slot


@numba.njit(cache=True)
def _sift_down(heap: np.ndarray, place: np.ndarray, key: np.ndarray, slot: int, size: int) -> None:
    item = heap[slot]
    while True:
        child = 2 * slot + 1
        if child >= size:
            break
        if child + 1 < size and key[heap[child + 1]] < key[heap[child]]:
            child += 1
        if key[item] <= key[heap[child]]:
            break
        heap[slot] = heap[child]
        place[heap[slot]] = slot
        slot = child
    heap[slot], place[item] = item, slot

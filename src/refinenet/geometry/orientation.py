"""Consistent orientation of unoriented normals: the refined normals are sign-free (the paper evaluates the
unoriented angle), while users reconstructing surfaces need them to point outwards.

* `orient_mst`: propagation over a minimum spanning tree of the k-NN graph (Hoppe et al. 1992, the method behind
  Open3D's `orient_normals_consistent_tangent_plane`). The walk runs on PCA normals, which turn gradually around an
  edge, and each given normal takes the sign of its point's: sharp normals are a poor field to walk on, since across
  an edge neighbours differ by up to 90 degrees or more and the sign test there is a coin toss (MFPS's normals of a
  10k-point fandisk came out 50% outward when walked on directly, 99.7% this way). The PCA takes more neighbours
  (GUIDE_K) than the graph links: on the graph's own 12 the field is as noisy as the cloud is dense (a 1M-point
  fandisk with 0.1% noise came out 98.0% outward from its exact normals, 0.5% noise 49%; with 30, 99.97% and 90%).
  The sign test compares one normal with the other reflected across the plane that bisects the chord between the
  two neighbourhoods' centroids, as on a circle through both points (König and Gumhold 2009 also judge a step by a
  curve through both points): on flat neighbours it is the dot product, and across a wedge sharper than a right
  angle, where the PCA field turns the short way round and the plain test flips the face beyond (a cone's base), it
  keeps the outward side. Chords shorter than MIN_CHORD times the noise take the plain test, which the noise would
  otherwise decide. Edge cost 1 - |test| makes the tree follow the surest decisions. In each connected part the
  walk starts at the point of largest z, whose normal on a closed surface points up (outwards). Measured in
  studies/results/orientation.md.
* `orient_viewpoint`: every normal towards a sensor position, for scans with a known origin.
"""

from __future__ import annotations

import numba
import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree

from refinenet.geometry.neighbors import build_tree, covariances, knn, smallest_eigenvectors

#: Neighbours per point in the propagation graph.
MST_K = 12
#: Neighbours of the PCA normals the walk runs on.
GUIDE_K = 30
#: Chords shorter than this many times the noise (the median spread along the PCA normals) take the plain test.
MIN_CHORD = 2.0
#: The PCA field is computed in this many parts of the cloud, to bound the memory of its neighbour lists.
FIELD_PARTS = 4
#: Added to every edge cost: scipy drops zero-weight edges, and parallel neighbours would have cost 0.
COST_FLOOR = 1e-6


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
    guide, centre, noise = _pca_field(points, min(GUIDE_K + 1, n))
    min_square = (MIN_CHORD * noise) ** 2
    k = min(k + 1, n)
    # The k-NN graph as CSR (row i: its k - 1 neighbours), built without per-edge copies: at 10M points every
    # array of one entry per edge costs about 1 GB.
    cols = knn(points, k, with_distances=False, index_dtype=np.int32)[1][:, 1:].ravel()
    graph = csr_matrix((_costs(guide, centre, cols, k - 1, min_square), cols, np.arange(0, len(cols) + 1, k - 1)),
                       shape=(n, n))
    del cols
    tree = minimum_spanning_tree(graph)
    del graph
    n_parts, part = connected_components(tree, directed=False)
    # One walk for all parts (a scan can have thousands): from an extra node n with normal +z, linked to each
    # part's highest point, so that the propagation itself turns every root upwards.
    by_height = np.lexsort((-points[:, 2], part))
    roots = by_height[np.searchsorted(part[by_height], np.arange(n_parts))]
    tree.resize((n + 1, n + 1))
    tree = tree + csr_matrix((np.ones(n_parts), (np.full(n_parts, n), roots)), shape=(n + 1, n + 1))
    oriented = np.vstack([guide, [0.0, 0.0, 1.0]])
    order, parent = breadth_first_order(tree, n, directed=False, return_predecessors=True)
    _propagate(oriented, centre, order, parent, n, min_square)
    return np.where((np.einsum("ij,ij->i", normals, oriented[:n]) < 0)[:, None], -normals, normals)


def _pca_field(points: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, float]:
    """PCA normals and centroids of every point's k nearest points, and the noise: the square root of the median
    smallest eigenvalue, the spread along the normal."""
    n = len(points)
    tree = build_tree(points)
    guide, centre, spread = np.empty((n, 3)), np.empty((n, 3)), np.empty(n)
    step = -(-n // FIELD_PARTS)
    for start in range(0, n, step):
        rows = slice(start, min(n, start + step))
        neighbours = knn(points, k, tree=tree, query=points[rows], with_distances=False, index_dtype=np.int32)[1]
        centre[rows], covs = covariances(points, neighbours)
        eigenvalues, guide[rows] = smallest_eigenvectors(covs)
        spread[rows] = eigenvalues[:, 0]
    return guide, centre, float(np.sqrt(max(np.median(spread), 0.0)))


@numba.njit(cache=True)
def _agreement(normals: np.ndarray, centres: np.ndarray, i: int, j: int, min_square: float) -> float:
    """n_i . n_j, with n_j reflected across the plane bisecting the chord c_i - c_j where the chord is long enough."""
    dot = normals[i, 0] * normals[j, 0] + normals[i, 1] * normals[j, 1] + normals[i, 2] * normals[j, 2]
    d0, d1, d2 = centres[i, 0] - centres[j, 0], centres[i, 1] - centres[j, 1], centres[i, 2] - centres[j, 2]
    square = d0 * d0 + d1 * d1 + d2 * d2
    if square > min_square:
        a = normals[i, 0] * d0 + normals[i, 1] * d1 + normals[i, 2] * d2
        b = normals[j, 0] * d0 + normals[j, 1] * d1 + normals[j, 2] * d2
        dot -= 2.0 * a * b / square
    return dot


@numba.njit(cache=True)
def _costs(normals: np.ndarray, centres: np.ndarray, cols: np.ndarray, per_row: int, min_square: float) -> np.ndarray:
    """1 - |agreement| of every edge (row e // per_row to cols[e]), plus COST_FLOOR."""
    cost = np.empty(len(cols))
    for e in range(len(cols)):
        cost[e] = 1.0 - abs(_agreement(normals, centres, e // per_row, cols[e], min_square)) + COST_FLOOR
    return cost


@numba.njit(cache=True)
def _propagate(normals: np.ndarray, centres: np.ndarray, order: np.ndarray, parent: np.ndarray, root: int,
               min_square: float) -> None:
    """In breadth-first order, flip each normal that disagrees with its (already oriented) parent's; the children
    of the extra node `root` (+z) are turned up."""
    for i in order[1:]:
        j = parent[i]
        agree = normals[i, 2] if j == root else _agreement(normals, centres, i, j, min_square)
        if agree < 0:
            normals[i, 0] = -normals[i, 0]
            normals[i, 1] = -normals[i, 1]
            normals[i, 2] = -normals[i, 2]

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
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree

from refinenet.geometry.neighbors import chunks, knn, knn_covariances, smallest_eigenvectors

#: Neighbours per point in the propagation graph.
MST_K = 12
#: Neighbours of the PCA normals the walk runs on.
GUIDE_K = 30
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
    guide = smallest_eigenvectors(knn_covariances(points, min(GUIDE_K + 1, n)))[1]
    k = min(k + 1, n)
    neighbours = knn(points, k, with_distances=False, index_dtype=np.int32)[1]
    # The k-NN graph as CSR (row i: its k - 1 neighbours), built without per-edge index or normal copies: at
    # 10M points every array of one entry per edge costs about 1 GB.
    cols = neighbours[:, 1:].ravel()
    del neighbours
    cost = np.empty(len(cols))
    for sl in chunks(n, k):
        edges = slice(sl.start * (k - 1), sl.stop * (k - 1))
        own = np.repeat(guide[sl], k - 1, axis=0)
        cost[edges] = 1.0 - np.abs(np.einsum("ij,ij->i", own, guide[cols[edges]])) + COST_FLOOR
    graph = csr_matrix((cost, cols, np.arange(0, len(cols) + 1, k - 1)), shape=(n, n))
    del cost, cols
    tree = minimum_spanning_tree(graph, overwrite=True)  # else scipy copies the graph (1.4 GB at 10M points)
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
    _propagate(oriented, order, parent)
    return np.where((np.einsum("ij,ij->i", normals, oriented[:n]) < 0)[:, None], -normals, normals)


@numba.njit(cache=True)
def _propagate(normals: np.ndarray, order: np.ndarray, parent: np.ndarray) -> None:
    """In breadth-first order, flip each normal that disagrees with its (already oriented) parent's."""
    for i in order[1:]:
        j = parent[i]
        if normals[i, 0] * normals[j, 0] + normals[i, 1] * normals[j, 1] + normals[i, 2] * normals[j, 2] < 0:
            normals[i, 0] = -normals[i, 0]
            normals[i, 1] = -normals[i, 1]
            normals[i, 2] = -normals[i, 2]

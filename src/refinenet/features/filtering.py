"""Multi-scale bilateral normal filtering (docs/algorithm.md §3, stage B).

Every point gets X normals: optionally its initial normal, then one bilateral average of the initial normals
of its ball neighbourhood per (sigma_s, sigma_r) pair. The spread of these X normals is what the per-point
frame (§4), the clustering (§5) and the network's normal branches read.

The ball pairs (i, j) come from a dual-tree query between a spatially compact chunk of points (consecutive in
the k-d tree's leaf order) and the whole cloud. The per-pair sums are sparse-times-dense products: column p of
a (chunk x pairs) CSC matrix holds the spatial weight of pair p in row i_p, so the pairs need no sorting.
Weights are evaluated in float32, the precision of the output. Each point's sum runs over its neighbours in
index order, whatever the k-d tree's shape, so a point gets bit-identical normals in any cloud that holds its
ball in the same order (a tile of a large cloud, `geometry.tiles`). Chunks write disjoint rows, so they run on
`native_threads` threads (the query, the sort and the products release the GIL) with the same result.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp

from refinenet.data.noise import bbox_diagonal
from refinenet.geometry.frames import target_sign
from refinenet.geometry.neighbors import CHUNK_ELEMENTS, build_tree, chunks
from refinenet.threads import native_threads, thread_map

#: Ball pairs per chunk, about 150 bytes of intermediates each (~40 MB). Run time hardly depends on it: 100k
#: points took 3.5-3.7 s of CPU with 100k to 2M pairs per chunk.
PAIRS_PER_CHUNK = CHUNK_ELEMENTS // 4


def bilateral_filter(points: np.ndarray, normals: np.ndarray, r_f: float = 0.03,
                     sigma_s: Sequence[float] = (1.0, 2.0), sigma_r: Sequence[float] = (0.1, 0.2, 0.35, 0.5),
                     include_initial: bool = True, orient_with_gt: np.ndarray | None = None,
                     length: float | None = None) -> np.ndarray:
    """Filtered normals `nf` (N x 3X, float32), ordered [n0,] f(s1, r1), .., f(s1, rR), f(s2, r1), ..

    Ball radius R_f = r_f * l_d (the point itself included; l_d is `length`, by default the bounding-box
    diagonal, `geometry.scale`), one pass over the *initial* normals:
    w_ij = exp(-|p_i - p_j|^2 / (sigma_s R_f / 2)^2) * exp(-2 (1 - |n_i . n_j|) / (2 sigma_r^2)).

    Clean-room signs (default): each n_j is flipped to n_i's side before it is summed, so f_i depends on no
    sign but n_i's own. Every summand then projects non-negatively on n_i and the self term contributes 1,
    so f_i . n_i > 0 by construction (the "flip f_i with f_i . n_i < 0" rule of §3 never fires).
    `orient_with_gt` (ground-truth normals) reproduces the release instead: the initial normals are first
    oriented to agree with the ground truth and then summed as they are; the emitted n0 is the oriented one.
    """
    points = np.asarray(points, dtype=np.float64)
    n0 = np.asarray(normals, dtype=np.float64)
    if orient_with_gt is not None:
        n0 = target_sign(n0, np.asarray(orient_with_gt, dtype=np.float64))
    n0 = n0.astype(np.float32)
    radius = r_f * (bbox_diagonal(points) if length is None else length)
    spatial_coef = np.asarray([(s * radius / 2) ** -2 for s in sigma_s], dtype=np.float32)
    range_coef = np.asarray([1.0 / s ** 2 for s in sigma_r], dtype=np.float32)  # 2(1 - |cos|) / (2 sigma_r^2)

    tree = build_tree(points)
    ball_sizes = tree.query_ball_point(points, radius, return_length=True, workers=native_threads())
    axes = [np.ascontiguousarray(n0[:, a]) for a in range(3)]  # 1-D gathers beat one N x 3 gather
    sums = np.empty((len(points), len(spatial_coef), len(range_coef), 3), dtype=np.float32)

    def fill(sl: slice) -> None:
        rows = tree.indices[sl]  # leaf order: a compact region, which keeps the dual-tree query cheap
        pairs = build_tree(points[rows]).sparse_distance_matrix(tree, radius, output_type="ndarray")
        pairs = pairs[np.lexsort((pairs["j"], pairs["i"]))]  # sums in neighbour order, not the tree's
        i, j = pairs["i"], pairs["j"]
        n_i, n_j = (np.stack([a[ids] for a in axes], axis=1) for ids in (rows[i], j))
        cos = np.einsum("pk,pk->p", n_i, n_j)
        if orient_with_gt is None:
            n_j *= np.where(cos < 0, -1.0, 1.0).astype(np.float32)[:, None]  # flip n_j to n_i's side
        range_w = np.exp((np.abs(cos) - 1.0)[:, None] * range_coef)  # (pairs, R)
        summands = (range_w[:, :, None] * n_j[:, None, :]).reshape(len(i), -1)  # (pairs, R * 3)
        d2 = (pairs["v"] ** 2).astype(np.float32)
        columns = np.arange(len(i) + 1)
        for s, inv_c2 in enumerate(spatial_coef):
            weights = sp.csc_array((np.exp(-d2 * inv_c2), i, columns), shape=(len(rows), len(i)))
            sums[rows, s] = (weights @ summands).reshape(len(rows), len(range_coef), 3)

    thread_map(fill, chunks(len(points), int(ball_sizes.max()), PAIRS_PER_CHUNK))
    filtered = sums / np.linalg.norm(sums, axis=-1, keepdims=True)
    filtered = filtered.reshape(len(points), -1)
    return np.concatenate([n0, filtered], axis=1) if include_initial else filtered

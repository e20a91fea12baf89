"""Point-module patches (docs/algorithm.md §6, stage E): a fixed-size, centred, unit-scaled, frame-aligned
neighbourhood.

Two neighbourhoods: `knn` (the release's, the code profile) and `ball` (the paper's: a random subset of at most
`max_points` points within `radius * l_d`, padded with the centre point, which is the origin after centring).
Centring and scaling make the patch independent of position and sampling density; rotating it by R^T (§4) puts it
in the same frame as the local normals. Called per batch (`index`), so the feature cache and the data loader share it.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from scipy.spatial import cKDTree

from refinenet.data.noise import bbox_diagonal
from refinenet.geometry.frames import to_local
from refinenet.geometry.neighbors import build_tree, chunks, knn


def point_patches(points: np.ndarray, mode: Literal["knn", "ball"] = "knn", k: int = 100, radius: float = 0.05,
                  max_points: int = 300, rng: np.random.Generator | None = None, frames: np.ndarray | None = None,
                  index: np.ndarray | None = None, tree: cKDTree | None = None,
                  length: float | None = None) -> np.ndarray:
    """Patches (M x P x 3, float32) around points[index] (all points when None); P = k or max_points.

    knn: the k nearest points (self included), divided by the distance to the k-th. ball: radius is a fraction of
    l_d (`length`, by default the bounding-box diagonal); a new random subset is drawn from `rng` on each call.
    `frames` (M x 3 x 3, those of the indexed points) rotates each patch into its point's frame.
    """
    points = np.asarray(points, dtype=np.float64)
    index = np.arange(len(points)) if index is None else np.asarray(index)
    tree = tree if tree is not None else build_tree(points)
    if mode == "knn":
        dist, idx = knn(points, k, tree=tree, query=points[index])
        scale = dist[:, -1]
    elif mode == "ball":
        ball = radius * (bbox_diagonal(points) if length is None else length)
        idx = _ball_subsets(points, index, ball, max_points, rng, tree)
        scale = np.full(len(index), ball)
    else:
        raise ValueError(f"unknown patch mode {mode!r}; expected 'knn' or 'ball'")
    axes = [np.ascontiguousarray(points[:, a]) for a in range(3)]  # 1-D gathers beat one M x P x 3 gather
    patches = np.empty((*idx.shape, 3), dtype=np.float32)
    for sl in chunks(len(index), idx.shape[1]):
        local = np.stack([x[idx[sl]] - x[index[sl], None] for x in axes], axis=2) / scale[sl, None, None]
        patches[sl] = local if frames is None else to_local(frames[sl], local)
    return patches


def _ball_subsets(points: np.ndarray, index: np.ndarray, radius: float, max_points: int,
                  rng: np.random.Generator | None, tree: cKDTree) -> np.ndarray:
    """Indices (M x max_points): a uniform random subset of each ball, padded with the centre's own index.

    The ball pairs come from a dual-tree query (no Python lists); sorting them by (row, random key) shuffles
    each ball, and the first `max_points` members of each row win.
    """
    rng = rng if rng is not None else np.random.default_rng()
    chosen = np.repeat(index[:, None], max_points, axis=1)
    sizes = tree.query_ball_point(points[index], radius, return_length=True, workers=-1)
    for sl in chunks(len(index), int(sizes.max())):
        pairs = build_tree(points[index[sl]]).sparse_distance_matrix(tree, radius, output_type="ndarray")
        row = pairs["i"]
        order = np.argsort((row << 32) + rng.integers(0, 1 << 32, len(row)))
        row, member = row[order], pairs["j"][order]
        count = np.bincount(row, minlength=len(chosen[sl]))
        rank = np.arange(len(row)) - (np.cumsum(count) - count)[row]
        keep = rank < max_points
        chosen[sl][row[keep], rank[keep]] = member[keep]
    return chosen

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
from refinenet.geometry.ball import BallGrid, ball_grid, random_ball_subsets
from refinenet.geometry.frames import to_local
from refinenet.geometry.neighbors import chunks, nearest_at


def point_patches(points: np.ndarray, mode: Literal["knn", "ball"] = "knn", k: int = 100, radius: float = 0.05,
                  max_points: int = 300, rng: np.random.Generator | None = None, frames: np.ndarray | None = None,
                  index: np.ndarray | None = None, tree: cKDTree | None = None, length: float | None = None,
                  grid: BallGrid | None = None, neighbours: np.ndarray | None = None) -> np.ndarray:
    """Patches (M x P x 3, float32) around points[index] (all points when None); P = k or max_points.

    knn: the k nearest points (self included), divided by the distance to the k-th. ball: radius is a fraction of
    l_d (`length`, by default the bounding-box diagonal); a new random subset is drawn from `rng` on each call.
    `frames` (M x 3 x 3, those of the indexed points) rotates each patch into its point's frame. `tree` (knn) and
    `grid` (ball, built for the ball's radius) are the cloud's search structures, when the caller keeps them;
    `neighbours` (M x k or wider), the indexed points' kNN lists, when the caller shares them (knn).
    """
    points = np.asarray(points, dtype=np.float64)
    index = np.arange(len(points)) if index is None else np.asarray(index)
    if mode == "knn":
        scale, idx = nearest_at(points, k, index, tree, neighbours)
    elif mode == "ball":
        ball = radius * (bbox_diagonal(points) if length is None else length)
        grid = grid if grid is not None and grid.radius == ball else ball_grid(points, ball)
        rng = rng if rng is not None else np.random.default_rng()
        idx = random_ball_subsets(grid, index, max_points, seed=int(rng.integers(0, 1 << 63)))
        scale = np.full(len(index), ball)
    else:
        raise ValueError(f"unknown patch mode {mode!r}; expected 'knn' or 'ball'")
    axes = [np.ascontiguousarray(points[:, a]) for a in range(3)]  # 1-D gathers beat one M x P x 3 gather
    patches = np.empty((*idx.shape, 3), dtype=np.float32)
    for sl in chunks(len(index), idx.shape[1]):
        local = np.stack([x[idx[sl]] - x[index[sl], None] for x in axes], axis=2) / scale[sl, None, None]
        patches[sl] = local if frames is None else to_local(frames[sl], local)
    return patches


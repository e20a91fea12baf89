"""Network inputs from cached clouds, built a whole batch at a time (docs/algorithm.md §0, §4, §6, §9).

Per sample: the X normals of nf in the local frame (3X), the point patch (P x 3, local frame), the X height maps
and, when ground truth is known, the target g in the local frame after the sign rule g . n_first >= 0 (§4). The
network predicts a local normal and inference rotates it back with the same frame.

Training samples are the points of one cluster; 20 % of each cloud's points (stratified by cluster, seeded) are
held out for validation, following [P] (§1.4 choice (a)). The split depends only on the cloud, its cluster ids
and the seed, so every cluster's network sees the same partition of the points.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
import torch
from scipy.spatial import cKDTree
from torch import Tensor
from torch.utils.data import DataLoader, Dataset

from refinenet.config import PatchConfig
from refinenet.data.noise import bbox_diagonal
from refinenet.features.cache import Features
from refinenet.features.patches import point_patches
from refinenet.geometry.ball import BallGrid, ball_grid
from refinenet.geometry.frames import target_sign, to_local
from refinenet.geometry.neighbors import build_tree
from refinenet.network.clustering import ClusterModel, cloud_clusters, local_normals
from refinenet.network.model import NetworkConfig


@dataclass
class PreparedCloud:
    """A cloud prepared for the network: its cached features and cluster ids; ground-truth normals only for
    training clouds (`prepare`).

    Feature rows may cover only some of the points (`centres`): a tile of a large cloud computes the network
    inputs of its own points while its margin supplies their neighbours. The k-d tree is built once here and
    reused by every batch's patch query.
    """

    points: np.ndarray
    """(N, 3) positions."""
    features: Features
    """Cached nf, frames and heights (`refinenet.features.cache`), one row per centre."""
    clusters: np.ndarray
    """(M,) cluster ids of the centres, 0..Kc-1."""
    normals: np.ndarray | None = None
    """(M, 3) ground-truth normals of the centres (unoriented; normalised here), or None at test time."""
    centres: np.ndarray | None = None
    """(M,) the point of each feature row; None: every point, in order."""
    length: float | None = None
    """l_d of ball patches (`geometry.scale`); None: the bounding-box diagonal of `points`."""
    neighbours: np.ndarray | None = None
    """(M, k or wider) the centres' kNN lists, when the caller has them (`neighbors.neighbour_lists`): knn patches
    then need no query."""
    tree: cKDTree = field(init=False, repr=False)
    _ball: BallGrid | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        self.points = np.asarray(self.points, dtype=np.float64)
        self.clusters = np.asarray(self.clusters)
        self.centres = np.arange(len(self.points)) if self.centres is None else np.asarray(self.centres)
        m = len(self.centres)
        if self.points.shape != (len(self.points), 3) or len(self.features) != m or self.clusters.shape != (m,) \
                or (self.neighbours is not None and len(self.neighbours) != m):
            raise ValueError(f"inconsistent cloud: points {self.points.shape}, {m} centres, {len(self.features)} "
                             f"feature rows, clusters {self.clusters.shape}"
                             + ("" if self.neighbours is None else f", neighbours {self.neighbours.shape}"))
        if self.normals is not None:
            normals = np.asarray(self.normals, dtype=np.float32)
            if normals.shape != (m, 3):
                raise ValueError(f"ground-truth normals have shape {normals.shape}, expected ({m}, 3)")
            self.normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
        self.tree = build_tree(self.points)
        self.length = bbox_diagonal(self.points) if self.length is None else self.length

    def ball_grid(self, radius: float) -> BallGrid:
        """The grid for ball patches of `radius` (absolute), built on first use and kept for every batch."""
        if self._ball is None or self._ball.radius != radius:
            self._ball = ball_grid(self.points, radius)
        return self._ball


def prepare(points: np.ndarray, features: Features, model: ClusterModel, normals: np.ndarray | None = None,
            centres: np.ndarray | None = None, length: float | None = None,
            neighbours: np.ndarray | None = None) -> PreparedCloud:
    """A cloud ready for training (with ground-truth `normals`) or inference: its centres assigned to clusters."""
    return PreparedCloud(points, features, cloud_clusters(model, features.nf, features.frames), normals, centres,
                         length, neighbours)


@dataclass(frozen=True)
class Inputs:
    """A batch of network inputs (numpy, float32), all in the local frames of their points."""

    normals: np.ndarray
    """(B, 3X) the X normals of nf."""
    points: np.ndarray | None
    """(B, P, 3) point patches, or None when the network has no point module."""
    heights: np.ndarray | None
    """(B, X, m, m) height maps, or None when the network has no height-map module."""
    target: np.ndarray | None
    """(B, 3) ground truth after the sign rule, or None without ground truth."""

    def __len__(self) -> int:
        return len(self.normals)

    def tensors(self, device: torch.device | str) -> tuple[Tensor, Tensor | None, Tensor | None]:
        """(normals, points, heights) on `device`, the argument order of `RefineNet.forward`."""
        def put(array: np.ndarray | None) -> Tensor | None:
            return None if array is None else torch.from_numpy(array).to(device)
        return torch.from_numpy(self.normals).to(device), put(self.points), put(self.heights)

    @staticmethod
    def concatenate(parts: Sequence[Inputs]) -> Inputs:
        """One batch from parts that all carry the same inputs."""
        def cat(name: str) -> np.ndarray | None:
            arrays = [getattr(part, name) for part in parts]
            return None if arrays[0] is None else np.concatenate(arrays)
        return Inputs(normals=cat("normals"), points=cat("points"), heights=cat("heights"), target=cat("target"))


def make_inputs(cloud: PreparedCloud, index: np.ndarray, patch: PatchConfig, network: NetworkConfig,
                rng: np.random.Generator) -> Inputs:
    """The inputs of feature rows `index` of one cloud; patches and heights only if the network reads them.

    `rng` draws the ball-mode subsets (unused by knn patches).
    """
    features = cloud.features
    frames = features.frames[index]
    nf = features.nf[index]
    points = None
    if network.uses_points:
        grid = cloud.ball_grid(patch.radius * cloud.length) if patch.mode == "ball" else None
        points = point_patches(cloud.points, patch.mode, k=patch.k, radius=patch.radius,
                               max_points=patch.max_points, rng=rng, frames=frames, index=cloud.centres[index],
                               tree=cloud.tree, length=cloud.length, grid=grid,
                               neighbours=None if cloud.neighbours is None else cloud.neighbours[index])
    heights = features.heights[index].astype(np.float32) if network.uses_hmps else None
    target = None
    if cloud.normals is not None:
        target = to_local(frames, target_sign(cloud.normals[index], nf[:, :3])).astype(np.float32)
    return Inputs(normals=local_normals(nf, frames).astype(np.float32), points=points, heights=heights,
                  target=target)


@dataclass(frozen=True)
class Samples:
    """Sample references: point `point[s]` of cloud `cloud[s]`."""

    cloud: np.ndarray
    point: np.ndarray

    def __len__(self) -> int:
        return len(self.point)


def holdout_mask(clusters: np.ndarray, fraction: float, rng: np.random.Generator) -> np.ndarray:
    """(N,) True for the validation points: round(fraction * n_c) random points of each cluster c."""
    keys = rng.random(len(clusters))
    order = np.lexsort((keys, clusters))
    labels, starts, counts = np.unique(clusters[order], return_index=True, return_counts=True)
    rank = np.arange(len(clusters)) - np.repeat(starts, counts)
    mask = np.empty(len(clusters), dtype=bool)
    mask[order] = rank < np.repeat(np.round(fraction * counts), counts)
    return mask


class ClusterData:
    """Training and validation samples of one cluster over a list of clouds, and their batches.

    Each cloud's split and point cap use the generator seeded with (seed, cloud position), so they are the same
    for every cluster and every run. `max_train_points_per_cloud` keeps a random subset (drawn once) of each
    cloud's training points, and caps its validation points in proportion (val_fraction / (1 - val_fraction)).
    With `resample`, epochs after the first draw that subset anew (`epoch_samples`): the same cost per epoch,
    but the training sees more of the clouds' points.
    """

    def __init__(self, clouds: Sequence[PreparedCloud], cluster: int, patch: PatchConfig, val_fraction: float,
                 seed: int, max_train_points_per_cloud: int | None, resample: bool = False):
        if not 0.0 < val_fraction < 1.0:
            raise ValueError(f"val_fraction must be in (0, 1), got {val_fraction}")
        if max_train_points_per_cloud is not None and max_train_points_per_cloud < 1:
            raise ValueError(f"max_train_points_per_cloud must be at least 1, got {max_train_points_per_cloud}")
        if any(cloud.normals is None for cloud in clouds):
            raise ValueError("training clouds need ground-truth normals")
        self.clouds, self.cluster, self.patch = list(clouds), cluster, patch
        self.seed, self.limit, self.resample = seed, max_train_points_per_cloud, resample
        max_val = None
        if max_train_points_per_cloud is not None:
            max_val = max(1, round(max_train_points_per_cloud * val_fraction / (1.0 - val_fraction)))
        self.pools: list[np.ndarray] = []  # each cloud's training points before the cap
        train, val = [], []
        for i, cloud in enumerate(self.clouds):
            rng = np.random.default_rng([seed, i])
            held_out = holdout_mask(cloud.clusters, val_fraction, rng)
            mine = cloud.clusters == cluster
            self.pools.append(np.flatnonzero(mine & ~held_out))
            train.append(_cap(self.pools[-1], max_train_points_per_cloud, rng))
            val.append(_cap(np.flatnonzero(mine & held_out), max_val, rng))
        self.train, self.val = _samples(train), _samples(val)
        if patch.mode == "ball":  # built here, before loader workers fork, so that they share the grids
            for cloud in self.clouds:
                cloud.ball_grid(patch.radius * cloud.length)

    def epoch_samples(self, epoch: int) -> Samples:
        """The training samples of `epoch` (1-based): `train`, or with `resample` after the first epoch a new
        capped subset of each cloud's training points, seeded by (seed, cloud position, epoch) so that a resumed
        epoch draws the same one. Every epoch has as many samples as `train`."""
        if not self.resample or epoch == 1:
            return self.train
        return _samples([_cap(pool, self.limit, np.random.default_rng([self.seed, i, epoch]))
                         for i, pool in enumerate(self.pools)])

    def batches(self, samples: Samples, batch_size: int, network: NetworkConfig, seed: Sequence[int],
                shuffle: bool, drop_last: bool, workers: int = 0) -> Iterable[Inputs]:
        """Batches in shuffled or stored order, built by `workers` processes (0: this one) while the caller trains.

        The order is drawn from a generator seeded with `seed`, and batch b draws its ball-mode patch subsets from
        one seeded with (*seed, b), so a batch is the same whichever process builds it: the worker count changes
        the speed, never the result.
        """
        order = np.random.default_rng(seed).permutation(len(samples)) if shuffle else np.arange(len(samples))
        stop = len(order) - len(order) % batch_size if drop_last else len(order)
        built = Batches(self, samples, order[:stop], batch_size, network, tuple(seed))
        if workers == 0:
            return (built[b] for b in range(len(built)))
        # A generator of its own: the workers' seeds would otherwise be drawn from torch's global one, the one
        # dropout draws from, and the trained weights would depend on the worker count.
        return DataLoader(built, batch_size=None, num_workers=workers, collate_fn=_as_built,
                          generator=torch.Generator().manual_seed(0))


class Batches(Dataset):
    """The batches of one pass over some samples, as a map-style dataset of whole batches, so that DataLoader
    workers build them in parallel (on a GPU one process building patches feeds the network too slowly)."""

    def __init__(self, data: ClusterData, samples: Samples, order: np.ndarray, batch_size: int,
                 network: NetworkConfig, seed: tuple[int, ...]):
        self.data, self.samples, self.order, self.batch_size = data, samples, order, batch_size
        self.network, self.seed = network, seed

    def __len__(self) -> int:
        return -(-len(self.order) // self.batch_size)

    def __getitem__(self, b: int) -> Inputs:
        """Batch b, its samples grouped by cloud (one patch query per cloud; the set, and so the loss, is the same)."""
        chosen = self.order[b * self.batch_size:(b + 1) * self.batch_size]
        clouds, points = self.samples.cloud[chosen], self.samples.point[chosen]
        rng = np.random.default_rng([*self.seed, b])
        data = self.data
        return Inputs.concatenate([make_inputs(data.clouds[c], points[clouds == c], data.patch, self.network, rng)
                                   for c in np.unique(clouds)])


def _as_built(batch: Inputs) -> Inputs:
    """DataLoader's conversion step, left out: a batch arrives as `Batches` built it."""
    return batch


def _cap(index: np.ndarray, limit: int | None, rng: np.random.Generator) -> np.ndarray:
    """A sorted random subset of at most `limit` entries of `index`."""
    if limit is None or len(index) <= limit:
        return index
    return np.sort(rng.choice(index, limit, replace=False))


def _samples(per_cloud: Sequence[np.ndarray]) -> Samples:
    cloud = np.repeat(np.arange(len(per_cloud)), [len(p) for p in per_cloud])
    point = np.concatenate(per_cloud) if per_cloud else np.zeros(0, dtype=np.int64)
    return Samples(cloud=cloud, point=point.astype(np.int64))

"""Normal-based clustering (docs/algorithm.md §5, stage D): PCA to 3 components, then k-means with Kc centres.

Points whose X normals spread alike (smooth regions, edges, corners) get the same cluster, and each cluster
gets its own network, so each network sees a narrower input distribution. The feature is nf in the local frame
(§4), unstandardised; clusters are 0-based here (the release's are 1..Kc).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from refinenet.config import ClusteringConfig
from refinenet.data.io import load_record, save_record
from refinenet.errors import InputError
from refinenet.features.cache import load_features
from refinenet.geometry.frames import to_local

#: PCA components kept (§5).
N_COMPONENTS = 3
#: The imbalance guard fires when the smallest cluster holds less than this fraction of the samples (§5).
MIN_CLUSTER_FRACTION = 0.01
#: Lloyd iterations per k-means run (MATLAB's default MaxIter).
MAX_ITERATIONS = 100


def local_normals(nf: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """The clustering feature and the network's normal input: every normal of nf (N, 3X) in its point's frame."""
    return to_local(frames, nf.reshape(len(nf), -1, 3)).reshape(len(nf), -1)


def pooled_local_normals(feature_paths: Sequence[str | Path]) -> np.ndarray:
    """The clustering features of every point of the given feature caches (the training clouds'), stacked."""
    return np.concatenate([local_normals(f.nf, f.frames) for f in (load_features(p)[0] for p in feature_paths)])


@dataclass(frozen=True)
class ClusterModel:
    """PCA projection and k-means centres: cluster of f = argmin_k |W (f - mean) - centres_k|^2."""

    mean: np.ndarray
    """(3X,) mean of the training features."""
    components: np.ndarray
    """(3, 3X) W, the leading principal axes as rows (each signed so its largest-magnitude weight is positive)."""
    centres: np.ndarray
    """(Kc, 3) k-means centres in PCA-score space."""

    def __post_init__(self) -> None:
        dim = self.mean.shape[0]
        if self.mean.ndim != 1 or self.components.shape != (N_COMPONENTS, dim) or self.centres.ndim != 2 \
                or self.centres.shape[1] != N_COMPONENTS or len(self.centres) < 1:
            raise ValueError(f"inconsistent cluster model shapes: mean {self.mean.shape}, components "
                             f"{self.components.shape}, centres {self.centres.shape}")

    @property
    def n_clusters(self) -> int:
        return len(self.centres)

    def scores(self, features: np.ndarray) -> np.ndarray:
        """(N, 3) PCA scores of features (N, 3X)."""
        return (np.asarray(features, dtype=np.float64) - self.mean) @ self.components.T


def fit_clusters(features: np.ndarray, config: ClusteringConfig, seed: int) -> ClusterModel:
    """PCA and k-means on the pooled training features (N, 3X), as §5 describes.

    At most `max_samples` rows (a seeded uniform subset) are used: PCA and centres of a few hundred thousand
    samples are as good as of millions, at a fraction of the time. Imbalance guard: when the smallest cluster
    holds < 1 % of the samples, k-means is run once more on the samples outside it; the new centres then
    assign every sample (including the outliers that formed the small cluster). Clusters are numbered by size,
    largest first.
    """
    features = np.asarray(features, dtype=np.float64)
    n_clusters, restarts, max_samples = config.n_clusters, config.restarts, config.max_samples
    if n_clusters < 1:
        raise ValueError(f"n_clusters must be at least 1, got {n_clusters}")
    if restarts < 1:
        raise ValueError(f"restarts must be at least 1, got {restarts}")
    if features.ndim != 2 or features.shape[1] < N_COMPONENTS:
        raise ValueError(f"features must have shape (N, 3X), got {features.shape}")
    rng = np.random.default_rng(seed)
    if max_samples is not None and len(features) > max_samples:
        features = features[np.sort(rng.choice(len(features), max_samples, replace=False))]
    mean = features.mean(axis=0)
    components = np.linalg.svd(features - mean, full_matrices=False)[2][:N_COMPONENTS]
    largest = np.take_along_axis(components, np.abs(components).argmax(axis=1)[:, None], axis=1)
    components *= np.sign(largest)
    scores = (features - mean) @ components.T
    centres = kmeans(scores, n_clusters, restarts, rng)
    labels = nearest(scores, centres)
    counts = np.bincount(labels, minlength=n_clusters)
    if counts.min() < MIN_CLUSTER_FRACTION * len(scores):
        centres = kmeans(scores[labels != counts.argmin()], n_clusters, restarts, rng)
    # Number the clusters by size, largest first: cluster 0's training is the longest job, and the workflow
    # starts the training jobs in cluster order so that it does not run last, alone.
    counts = np.bincount(nearest(scores, centres), minlength=n_clusters)
    centres = centres[np.argsort(-counts, kind="stable")]
    return ClusterModel(mean=mean, components=components, centres=centres)


def cloud_clusters(model: ClusterModel, nf: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """Cluster ids (N,) of a cloud's points from its cached filtered normals and frames."""
    return assign(model, local_normals(nf, frames))


def assign(model: ClusterModel, features: np.ndarray) -> np.ndarray:
    """Cluster ids (N,) in 0..Kc-1 of features (N, 3X): the nearest centre in PCA-score space."""
    return nearest(model.scores(features), model.centres)


def nearest(x: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Index of the nearest centre (squared Euclidean distance) of each row of x."""
    return _sq_distances(x, centres).argmin(axis=1)


def kmeans(x: np.ndarray, k: int, restarts: int, rng: np.random.Generator) -> np.ndarray:
    """Centres (k, d) of the best of `restarts` Lloyd runs (lowest within-cluster sum of squares), each seeded by
    k-means++. A cluster that empties during a run is moved onto the sample farthest from its centre (MATLAB's
    'singleton' rule)."""
    if len(x) < k:
        raise ValueError(f"{len(x)} samples are too few for {k} clusters")
    best, best_cost = None, np.inf
    for _ in range(restarts):
        centres = _kmeans_plus_plus(x, k, rng)
        labels = None
        for _ in range(MAX_ITERATIONS):
            d2 = _sq_distances(x, centres)
            new = d2.argmin(axis=1)
            counts = np.bincount(new, minlength=k)
            while (counts == 0).any():  # each pass moves a different sample, so this ends
                far = d2[np.arange(len(x)), new].argmax()
                new[far] = counts.argmin()
                d2[far] = -np.inf
                counts = np.bincount(new, minlength=k)
            if labels is not None and np.array_equal(new, labels):
                break
            labels = new
            sums = np.stack([np.bincount(labels, x[:, j], minlength=k) for j in range(x.shape[1])], axis=1)
            centres = sums / counts[:, None]
        cost = _sq_distances(x, centres).min(axis=1).sum()
        if cost < best_cost:
            best, best_cost = centres, cost
    return best


def _kmeans_plus_plus(x: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    """k-means++ seeding: the first centre uniform, each next one drawn with probability proportional to the
    squared distance to the nearest centre chosen so far."""
    centres = [x[rng.integers(len(x))]]
    d2 = _sq_distances(x, centres[0][None])[:, 0]
    for _ in range(1, k):
        total = d2.sum()
        pick = rng.choice(len(x), p=d2 / total) if total > 0 else rng.integers(len(x))
        centres.append(x[pick])
        d2 = np.minimum(d2, _sq_distances(x, x[pick][None])[:, 0])
    return np.stack(centres)


def _sq_distances(x: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """(N, k) squared distances, by differences (not the expanded form, which cancels badly near a centre)."""
    return ((x[:, None, :] - centres[None, :, :]) ** 2).sum(axis=2)


def save_cluster_model(path: str | Path, model: ClusterModel, meta: dict[str, Any]) -> None:
    """Write the model as .npz atomically, with `meta` (JSON-serialisable: seed, Kc, feature config...)."""
    save_record(path, {"mean": model.mean, "components": model.components, "centres": model.centres}, meta)


def load_cluster_model(path: str | Path) -> tuple[ClusterModel, dict[str, Any]]:
    """The model and meta written by `save_cluster_model`; InputError for a missing or malformed file."""
    arrays, meta = load_record(path, ("mean", "components", "centres"), "cluster model")
    try:
        model = ClusterModel(mean=arrays["mean"], components=arrays["components"], centres=arrays["centres"])
    except ValueError as err:
        raise InputError(path, f"not a cluster model ({err})") from None
    return model, meta

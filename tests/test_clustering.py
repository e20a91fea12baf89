"""Clustering (docs/algorithm.md §5): blob recovery, determinism, the imbalance guard, Kc = 1, the local feature,
files."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from settings import clustering_config

import refinenet.network.clustering as clustering
from refinenet.errors import InputError
from refinenet.network.clustering import (
    ClusterModel,
    assign,
    fit_clusters,
    load_cluster_model,
    local_normals,
    save_cluster_model,
)


def blobs(sizes: list[int], centres: np.ndarray, seed: int = 0, spread: float = 0.05,
          dim: int = 27) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian blobs around 3-d centres, embedded in a random 3-d subspace of R^dim plus small off-subspace noise."""
    rng = np.random.default_rng(seed)
    labels = np.repeat(np.arange(len(sizes)), sizes)
    low = centres[labels] + rng.normal(0.0, spread, (len(labels), 3))
    basis = np.linalg.qr(rng.normal(size=(dim, 3)))[0].T
    return low @ basis + 0.3 + rng.normal(0.0, 0.005, (len(labels), dim)), labels


def same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    """Labels equal up to a permutation of the ids."""
    pairs = np.unique(np.stack([a, b], axis=1), axis=0)
    return len(pairs) == len(np.unique(a)) == len(np.unique(b))


CORNERS = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [-1.0, -1.0, 0]])


def test_separated_blobs_are_recovered_and_numbered_by_size():
    """Blobs of 900, 600, 300 and 1,200 samples: cluster 0 is the largest (the workflow trains it first)."""
    features, truth = blobs([900, 600, 300, 1200], CORNERS)
    model = fit_clusters(features, clustering_config(n_clusters=4), seed=3)
    labels = assign(model, features)
    assert labels.dtype.kind == "i" and labels.min() >= 0 and labels.max() <= 3
    assert same_partition(labels, truth)
    assert np.bincount(labels).tolist() == [1200, 900, 600, 300]


def test_subsampled_fit_is_deterministic_and_still_recovers_the_blobs():
    features, truth = blobs([3000, 3000, 3000, 3000], CORNERS, seed=1)
    first = fit_clusters(features, clustering_config(n_clusters=4, max_samples=400), seed=7)
    second = fit_clusters(features, clustering_config(n_clusters=4, max_samples=400), seed=7)
    for name in ("mean", "components", "centres"):
        np.testing.assert_array_equal(getattr(first, name), getattr(second, name))
    assert same_partition(assign(first, features), truth)


def test_imbalance_guard_refits_without_the_tiny_cluster(monkeypatch):
    """Three blobs and 0.3 % far outliers: k-means gives the outliers a centre of their own (checked with the
    guard switched off); the guard refits on the rest, so no centre sits at the outliers and every cluster has
    >= 1 % of the samples."""
    centres = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [30.0, 30.0, 30.0]])
    features, truth = blobs([3300, 3300, 3300, 30], centres, seed=2)

    def distance_to_outliers(model: ClusterModel) -> float:
        outliers = model.scores(features[truth == 3]).mean(axis=0)
        return float(np.linalg.norm(model.centres - outliers, axis=1).min())

    model = fit_clusters(features, clustering_config(n_clusters=4), seed=0)
    assert distance_to_outliers(model) > 10.0
    assert np.bincount(assign(model, features), minlength=4).min() >= 0.01 * len(features)
    monkeypatch.setattr(clustering, "MIN_CLUSTER_FRACTION", 0.0)
    assert distance_to_outliers(fit_clusters(features, clustering_config(n_clusters=4), seed=0)) < 1.0


def test_single_cluster():
    features, _ = blobs([200, 200], CORNERS[:2])
    model = fit_clusters(features, clustering_config(n_clusters=1), seed=0)
    assert model.n_clusters == 1 and model.centres.shape == (1, 3)
    np.testing.assert_array_equal(assign(model, features), np.zeros(400, dtype=int))


def test_local_normals_rotate_every_normal_into_the_frame():
    rng = np.random.default_rng(0)
    frames = Rotation.random(50, random_state=1).as_matrix()
    local = rng.normal(size=(50, 9, 3))
    nf = np.einsum("nij,nxj->nxi", frames, local).reshape(50, 27)
    np.testing.assert_allclose(local_normals(nf, frames), local.reshape(50, 27), atol=1e-12)


def test_round_trip(tmp_path):
    features, _ = blobs([100, 100], CORNERS[:2])
    model = fit_clusters(features, clustering_config(n_clusters=2), seed=0)
    path = tmp_path / "clusters.npz"
    save_cluster_model(path, model, {"seed": 0})
    loaded, meta = load_cluster_model(path)
    assert meta == {"seed": 0}
    np.testing.assert_array_equal(assign(loaded, features), assign(model, features))
    np.save(tmp_path / "other.npy", np.zeros(3))
    with pytest.raises(InputError, match="not a cluster model"):
        load_cluster_model(tmp_path / "other.npy")


def test_inconsistent_model_and_bad_arguments():
    with pytest.raises(ValueError, match="shapes"):
        ClusterModel(mean=np.zeros(27), components=np.zeros((3, 24)), centres=np.zeros((4, 3)))
    with pytest.raises(ValueError, match="n_clusters"):
        fit_clusters(np.zeros((10, 27)), clustering_config(n_clusters=0), seed=0)
    with pytest.raises(ValueError, match="too few"):
        fit_clusters(np.random.default_rng(0).random((3, 27)), clustering_config(n_clusters=4), seed=0)

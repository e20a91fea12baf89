"""Refining a whole cloud (docs/algorithm.md §10): the frame round trip, merging across clusters, the empty-cluster
fallback, batch-size independence and loading trained networks."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from settings import clustering_config, inference_config, patch_config, train_config
from test_dataset import cube_cloud
from torch import Tensor, nn

from refinenet.errors import InputError
from refinenet.network.clustering import assign, fit_clusters, local_normals
from refinenet.network.inference import load_networks, refine_normals
from refinenet.network.model import NetworkConfig, RefineNet, preset
from refinenet.network.training import cluster_data, cluster_dir, train_cluster

FULL = preset("release")


class FirstNormal(nn.Module):
    """Returns the first local normal unchanged, so refine_normals must give back n_first in the world frame."""

    def __init__(self, config: NetworkConfig = FULL):
        super().__init__()
        self.config = config

    def forward(self, normals: Tensor, points: Tensor, heights: Tensor) -> Tensor:
        assert points.shape[1:] == (100, 3) and heights.shape[1:] == (9, 7, 7)
        return normals[:, :3]


class LocalZ(FirstNormal):
    """Always predicts the local z axis, i.e. e3 in the world frame."""

    def forward(self, normals: Tensor, points: Tensor, heights: Tensor) -> Tensor:
        return torch.tensor([0.0, 0.0, 1.0]).expand(len(normals), 3)


@pytest.fixture(scope="module")
def cloud():
    return cube_cloud(700, seed=5)


@pytest.fixture(scope="module")
def cluster_model(cloud):
    features = local_normals(cloud.features.nf, cloud.features.frames)
    return fit_clusters(features, clustering_config(n_clusters=2), seed=0)


def refine(cloud, cluster_model, networks, device="cpu", **changes) -> np.ndarray:
    config = inference_config(device=device, **changes)
    return refine_normals(cloud.points, cloud.features, cluster_model, networks, patch_config(), config)


def test_identity_network_returns_the_initial_normals(cloud, cluster_model):
    clusters = assign(cluster_model, local_normals(cloud.features.nf, cloud.features.frames))
    assert np.bincount(clusters).min() > 20  # both clusters are exercised
    out = refine(cloud, cluster_model, {0: FirstNormal(), 1: FirstNormal()}, batch_size=64)
    assert out.shape == (700, 3) and out.dtype == np.float32
    np.testing.assert_allclose(out, cloud.features.n_first, atol=1e-6)


def test_clusters_are_merged_by_membership(cloud, cluster_model):
    clusters = assign(cluster_model, local_normals(cloud.features.nf, cloud.features.frames))
    out = refine(cloud, cluster_model, {0: FirstNormal(), 1: LocalZ()}, batch_size=100)
    np.testing.assert_allclose(out[clusters == 0], cloud.features.n_first[clusters == 0], atol=1e-6)
    np.testing.assert_allclose(out[clusters == 1], cloud.features.frames[clusters == 1, :, 2], atol=1e-6)
    # A cluster without a network (trained as empty) keeps the first normal.
    out = refine(cloud, cluster_model, {1: LocalZ()})
    np.testing.assert_array_equal(out[clusters == 0], cloud.features.n_first[clusters == 0])


def test_batch_size_does_not_change_the_result(cloud, cluster_model):
    """A random full network on the smaller cluster (the identity on the other keeps the test fast)."""
    torch.manual_seed(0)
    networks = {0: FirstNormal(), 1: RefineNet(FULL).eval()}
    small = refine(cloud, cluster_model, networks, batch_size=7)
    large = refine(cloud, cluster_model, networks, batch_size=700)
    np.testing.assert_allclose(small, large, atol=1e-5)


def test_unknown_cluster_is_an_error(cloud, cluster_model):
    with pytest.raises(ValueError, match=r"clusters \[2\]"):
        refine(cloud, cluster_model, {2: FirstNormal()})


def test_load_networks(tmp_path, cloud, cluster_model):
    """Cluster 0 trained one epoch, cluster 1 empty: the loaded networks refine like the trained one, fused or not."""
    normals_only = preset("release", features="normals")
    config = train_config(batch_size=64, max_epochs=1, threads=1)
    train_cluster(config, normals_only, cluster_data([cloud], 0, config, patch_config()), cluster_dir(tmp_path, 0),
                  progress=False)
    train_cluster(config, normals_only, cluster_data([cloud], 7, config, patch_config()), cluster_dir(tmp_path, 1),
                  progress=False)
    folders = [cluster_dir(tmp_path, c) for c in range(3)]
    plain = load_networks(folders[:2], normals_only, "cpu", fuse=False)
    fused = load_networks(folders[:2], normals_only, "cpu")
    assert set(plain) == set(fused) == {0}
    np.testing.assert_allclose(refine(cloud, cluster_model, fused), refine(cloud, cluster_model, plain), atol=1e-5)
    with pytest.raises(InputError, match="another architecture"):
        load_networks(folders[:2], FULL, "cpu")
    with pytest.raises(InputError, match="neither trained nor marked empty"):
        load_networks(folders, normals_only, "cpu")


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_cuda_matches_cpu(cloud, cluster_model):
    torch.manual_seed(0)
    networks = {0: FirstNormal(), 1: RefineNet(FULL).eval()}
    cpu = refine(cloud, cluster_model, networks)
    cuda = refine(cloud, cluster_model, networks, device="cuda")
    np.testing.assert_allclose(cuda, cpu, atol=1e-4)

"""Batched network inputs from cached clouds: shapes, the target sign rule, the stratified hold-out, caps, batching."""

from __future__ import annotations

import numpy as np
import pytest
from settings import cluster_samples, feature_config, patch_config
from test_features import noisy_cube

from refinenet.features.cache import compute_features
from refinenet.geometry.frames import to_local
from refinenet.network.dataset import PreparedCloud, holdout_mask, make_inputs
from refinenet.network.model import preset

FULL = preset("release")


def cube_cloud(n: int, seed: int, n_clusters: int = 3, with_truth: bool = True) -> PreparedCloud:
    """A noisy cube with cached features and arbitrary cluster ids (by face pair)."""
    points, normals, initial = noisy_cube(n, seed)
    features = compute_features(points, initial, feature_config())
    clusters = np.abs(normals).argmax(axis=1) % n_clusters
    return PreparedCloud(points, features, clusters, normals if with_truth else None)


@pytest.fixture(scope="module")
def clouds() -> list[PreparedCloud]:
    return [cube_cloud(1200, seed=0), cube_cloud(900, seed=1)]


def test_batch_shapes_and_local_frame(clouds):
    cloud = clouds[0]
    index = np.arange(0, 1200, 7)
    inputs = make_inputs(cloud, index, patch_config(), FULL, np.random.default_rng(0))
    b = len(index)
    assert inputs.normals.shape == (b, 27) and inputs.normals.dtype == np.float32
    assert inputs.points.shape == (b, 100, 3) and inputs.points.dtype == np.float32
    assert inputs.heights.shape == (b, 9, 7, 7) and inputs.heights.dtype == np.float32
    assert inputs.target.shape == (b, 3) and inputs.target.dtype == np.float32
    frames = cloud.features.frames[index]
    np.testing.assert_allclose(inputs.normals[:, :3], to_local(frames, cloud.features.nf[index, :3]), atol=1e-6)
    assert (inputs.normals[:, 2] > 0).all()  # e3 . n_first > 0 (§4)
    np.testing.assert_array_equal(inputs.points[:, 0], 0.0)  # the point itself, centred
    assert np.linalg.norm(inputs.points, axis=2).max() <= 1.0 + 1e-5  # scaled by the 100th neighbour
    normals, points, heights = inputs.tensors("cpu")
    assert normals.shape == (b, 27) and points.shape == (b, 100, 3) and heights.shape == (b, 9, 7, 7)


def test_target_sign_rule_gives_positive_z(clouds):
    """The initial normals are the ground truth up to sign: flipped onto n_first, the target is n_first itself, so
    its local z is n_first . e3 > 0."""
    cloud = clouds[0]
    index = np.arange(1200)
    target = make_inputs(cloud, index, patch_config(), preset("release", features="normals"),
                         np.random.default_rng(0)).target
    assert (target[:, 2] > 0).all()
    np.testing.assert_allclose(np.linalg.norm(target, axis=1), 1.0, atol=1e-6)


def test_unused_inputs_are_not_built(clouds):
    inputs = make_inputs(clouds[0], np.arange(5), patch_config(), preset("release", features="normals"),
                         np.random.default_rng(0))
    assert inputs.points is None and inputs.heights is None
    test_cloud = PreparedCloud(clouds[0].points, clouds[0].features, clouds[0].clusters)
    assert make_inputs(test_cloud, np.arange(5), patch_config(), FULL, np.random.default_rng(0)).target is None


def test_ball_patches_have_max_points(clouds):
    patch = patch_config(mode="ball", radius=0.05, max_points=64)
    inputs = make_inputs(clouds[0], np.arange(10), patch, FULL, np.random.default_rng(0))
    assert inputs.points.shape == (10, 64, 3)


def test_holdout_mask_is_stratified_and_seeded():
    clusters = np.repeat([0, 1, 2, 3], [1000, 37, 5, 1])
    mask = holdout_mask(clusters, 0.2, np.random.default_rng(0))
    assert [int(mask[clusters == c].sum()) for c in range(4)] == [200, 7, 1, 0]
    np.testing.assert_array_equal(mask, holdout_mask(clusters, 0.2, np.random.default_rng(0)))
    assert not np.array_equal(mask, holdout_mask(clusters, 0.2, np.random.default_rng(1)))


def test_split_is_disjoint_complete_and_shared_by_all_clusters(clouds):
    per_cluster = [cluster_samples(clouds, c, seed=5) for c in range(3)]
    for i, cloud in enumerate(clouds):
        val = np.zeros(len(cloud.points), dtype=bool)
        train = np.zeros(len(cloud.points), dtype=bool)
        for c, data in enumerate(per_cluster):
            v = data.val.point[data.val.cloud == i]
            t = data.train.point[data.train.cloud == i]
            assert (cloud.clusters[v] == c).all() and (cloud.clusters[t] == c).all()
            assert len(v) == round(0.2 * (cloud.clusters == c).sum())
            val[v], train[t] = True, True
        assert not (val & train).any() and (val | train).all()
        np.testing.assert_array_equal(val, holdout_mask(cloud.clusters, 0.2, np.random.default_rng([5, i])))


def test_cap_is_drawn_once(clouds):
    capped = cluster_samples(clouds, 0, seed=1, max_train_points_per_cloud=40)
    again = cluster_samples(clouds, 0, seed=1, max_train_points_per_cloud=40)
    for i in range(2):
        assert (capped.train.cloud == i).sum() == 40 and (capped.val.cloud == i).sum() == 10
    np.testing.assert_array_equal(capped.train.point, again.train.point)
    np.testing.assert_array_equal(capped.val.point, again.val.point)


def test_resampled_cap_draws_each_epoch_anew_from_the_training_points_only(clouds):
    fixed = cluster_samples(clouds, 0, seed=1, max_train_points_per_cloud=40)
    data = cluster_samples(clouds, 0, seed=1, max_train_points_per_cloud=40, resample_points=True)
    np.testing.assert_array_equal(data.epoch_samples(1).point, fixed.train.point)
    np.testing.assert_array_equal(fixed.epoch_samples(3).point, fixed.train.point)
    np.testing.assert_array_equal(data.val.point, fixed.val.point)
    seen = [set() for _ in clouds]
    for epoch in range(1, 6):
        samples = data.epoch_samples(epoch)
        np.testing.assert_array_equal(samples.point, data.epoch_samples(epoch).point)  # a resumed epoch's draw
        for i in range(len(clouds)):
            points = samples.point[samples.cloud == i]
            assert len(points) == 40 and len(set(points)) == 40
            assert set(points) <= set(data.pools[i]) and not set(points) & set(data.val.point[data.val.cloud == i])
            seen[i] |= set(points)
    # Cluster 0 holds about 1/3 of 1200 and 900 points, 80% of them training points (about 320 and 240): five
    # draws of 40 see about 156 and 144 of them, against 40 for the cap drawn once.
    for i in range(len(clouds)):
        assert 100 < len(seen[i]) <= len(data.pools[i])


def test_batches(clouds):
    data = cluster_samples(clouds, 1, seed=0)
    n = len(data.train)
    sizes = [len(b) for b in data.batches(data.train, 64, FULL, (0,), shuffle=True, drop_last=True)]
    assert sizes == [64] * (n // 64)
    sizes = [len(b) for b in data.batches(data.train, 64, FULL, (0,), shuffle=True, drop_last=False)]
    assert sum(sizes) == n and sizes[-1] == n - 64 * (n // 64)
    # One batch over both clouds = each cloud's inputs, grouped by cloud.
    (whole,) = data.batches(data.val, len(data.val), FULL, (0,), shuffle=False, drop_last=False)
    parts = [make_inputs(clouds[i], data.val.point[data.val.cloud == i], patch_config(), FULL,
                         np.random.default_rng(0)) for i in range(2)]
    for name in ("normals", "points", "heights", "target"):
        np.testing.assert_array_equal(getattr(whole, name), np.concatenate([getattr(p, name) for p in parts]))


def test_loader_workers_build_the_same_batches(clouds):
    """Ball patches draw random subsets: two worker processes must build exactly the batches this process builds,
    in the same order, and another seed other subsets."""
    data = cluster_samples(clouds, 1, seed=0, patch=patch_config(mode="ball", radius=0.1, max_points=32))
    here = list(data.batches(data.train, 64, FULL, (3, 1), shuffle=True, drop_last=True))
    there = list(data.batches(data.train, 64, FULL, (3, 1), shuffle=True, drop_last=True, workers=2))
    other = list(data.batches(data.train, 64, FULL, (3, 2), shuffle=True, drop_last=True))
    assert len(here) == len(there) == len(data.train) // 64 >= 2
    for a, b in zip(here, there, strict=True):
        for name in ("normals", "points", "heights", "target"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert not np.array_equal(here[0].points, other[0].points)


def test_errors(clouds):
    with pytest.raises(ValueError, match="ground-truth"):
        cluster_samples([PreparedCloud(clouds[0].points, clouds[0].features, clouds[0].clusters)], 0)
    with pytest.raises(ValueError, match="val_fraction"):
        cluster_samples(clouds, 0, val_fraction=1.0)
    with pytest.raises(ValueError, match="inconsistent"):
        PreparedCloud(clouds[0].points[:10], clouds[0].features, clouds[0].clusters)

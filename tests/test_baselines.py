"""PCA and Jet normals on shapes with known normals, and agreement of our PCA with Open3D's."""

import numpy as np
import pytest
from known_shapes import fibonacci_sphere

from refinenet.estimators.baselines import jet_normals, pca_normals
from refinenet.evaluation.metrics import unoriented_angles
from refinenet.geometry.neighbors import covariances, knn


def test_knn_includes_self_first_and_rejects_large_k():
    pts = np.random.default_rng(1).normal(size=(200, 3))
    dist, idx = knn(pts, 10)
    np.testing.assert_array_equal(idx[:, 0], np.arange(200))
    assert (np.diff(dist, axis=1) >= 0).all()
    with pytest.raises(ValueError, match="only 200 points"):
        knn(pts, 201)


def test_covariances_match_numpy_far_from_origin():
    pts = np.random.default_rng(2).normal(size=(300, 3)) + 1e4
    _, idx = knn(pts, 20)
    centroids, covs = covariances(pts, idx)
    for i in (0, 150, 299):
        nb = pts[idx[i]]
        np.testing.assert_allclose(covs[i], np.cov(nb.T, bias=True), atol=1e-9)
        np.testing.assert_allclose(centroids[i], nb.mean(axis=0), atol=1e-9)


@pytest.mark.parametrize("estimator", [pca_normals, jet_normals])
def test_plane_is_exact(estimator):
    rng = np.random.default_rng(3)
    uv = rng.uniform(-1, 1, size=(2000, 2))
    normal = np.array([1.0, 2.0, 2.0]) / 3.0
    basis = np.linalg.svd(normal[None])[2][1:]
    points = uv @ basis + 5.0
    np.testing.assert_allclose(unoriented_angles(estimator(points, 30), np.tile(normal, (2000, 1))), 0, atol=1e-5)


def test_sphere_errors():
    points = fibonacci_sphere(5000)
    pca = unoriented_angles(pca_normals(points, 30), points).mean()
    jet = unoriented_angles(jet_normals(points, 30), points).mean()
    assert pca < 0.5  # PCA is biased only by curvature across the patch
    assert jet < 0.01  # a degree-2 jet represents the sphere locally
    assert jet < pca / 20


def test_jet_beats_pca_on_curved_noise_free_cylinder():
    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    z = np.linspace(0, 3, 50)
    tt, zz = np.meshgrid(t, z)
    points = np.stack([np.cos(tt).ravel(), np.sin(tt).ravel(), zz.ravel()], axis=1)
    truth = points * np.array([1, 1, 0])
    interior = (points[:, 2] > 0.5) & (points[:, 2] < 2.5)
    err_pca = unoriented_angles(pca_normals(points, 60), truth)[interior].mean()
    err_jet = unoriented_angles(jet_normals(points, 60), truth)[interior].mean()
    assert err_jet < 0.01 < err_pca


def test_pca_agrees_with_open3d():
    import open3d as o3d

    rng = np.random.default_rng(4)
    points = fibonacci_sphere(20000) + rng.normal(scale=0.002, size=(20000, 3))
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=100), fast_normal_computation=False)
    angles = unoriented_angles(pca_normals(points, 100), np.asarray(pcd.normals))
    assert angles.mean() < 0.1

"""PCA and Jet normals on shapes with known normals, and agreement of our PCA with Open3D's."""

import numpy as np
import pytest
from known_shapes import fibonacci_sphere

from refinenet.estimators.baselines import jet_fit, jet_normals, pca_normals
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


@pytest.mark.parametrize("degree", [1, 2, 3])
def test_jet_fit_is_the_least_squares_height_function_in_the_pca_frame(degree):
    """Each neighbourhood's jet against its definition solved by numpy's least squares: in the neighbourhood's PCA
    frame (normal-like axis first) centred on the query point and scaled to unit size, z = sum c_ij x^i y^j over
    i + j <= degree; the normal is (1, -c_x, -c_y) in that frame; the residual is the RMS height over k - #c."""
    rng = np.random.default_rng(degree)
    points = rng.normal(size=(400, 3)) * [1.0, 1.0, 0.1] + [1e3, -2e3, 5e2]
    _, idx = knn(points, 25)
    normals, residuals = jet_fit(points, idx, degree)
    _, covs = covariances(points, idx)
    for i in (0, 17, 399):
        frame = np.linalg.eigh(covs[i])[1]
        uvw = (points[idx[i]] - points[idx[i, 0]]) @ frame
        uvw /= np.linalg.norm(uvw, axis=1).max()
        columns = np.stack([uvw[:, 1] ** (t - j) * uvw[:, 2] ** j for t in range(degree + 1) for j in range(t + 1)], 1)
        coef, *_ = np.linalg.lstsq(columns, uvw[:, 0], rcond=None)
        normal = frame @ [1.0, -coef[1], -coef[2]]
        assert unoriented_angles(normals[i:i + 1], normal[None, :] / np.linalg.norm(normal))[0] < 1e-6
        rms = np.linalg.norm(uvw[:, 0] - columns @ coef) / np.sqrt(25 - len(coef))
        scale = np.linalg.norm(points[idx[i]] - points[idx[i, 0]], axis=1).max()
        np.testing.assert_allclose(residuals[i], rms * scale, rtol=1e-6)


def test_jet_residual_is_the_noise_of_a_noisy_plane():
    """On a plane with Gaussian noise sigma along its normal, the RMS residual (squares over k minus the six
    coefficients) estimates sigma."""
    rng = np.random.default_rng(5)
    points = np.c_[rng.uniform(-1, 1, size=(20_000, 2)), rng.normal(0, 0.01, 20_000)]
    _, idx = knn(points, 200)
    _, residuals = jet_fit(points, idx)
    assert abs(np.median(residuals) / 0.01 - 1) < 0.05


def test_pca_agrees_with_open3d():
    import open3d as o3d

    rng = np.random.default_rng(4)
    points = fibonacci_sphere(20000) + rng.normal(scale=0.002, size=(20000, 3))
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=100), fast_normal_computation=False)
    angles = unoriented_angles(pca_normals(points, 100), np.asarray(pcd.normals))
    assert angles.mean() < 0.1

"""The smooth-point jet (`FeatureConfig.smooth_jet`): the noise it measures, the points it takes (a sphere's, a
cube's faces) and leaves (the cube's edges), and the feature cache built on it."""

from __future__ import annotations

import numpy as np
from known_shapes import fibonacci_sphere
from settings import feature_config
from test_features import noisy_cube

from refinenet.estimators.baselines import jet_normals, pca_normals
from refinenet.estimators.smooth_jet import point_noise, smooth_jet_normals
from refinenet.evaluation.metrics import unoriented_angles
from refinenet.features.cache import compute_features


def test_point_noise_is_proportional_to_the_noise_of_a_plane():
    """On a plane with Gaussian noise of sigma along its normal (small against the neighbourhoods, as on the
    benchmark's clouds), the median residual of the K = 20 jets is a little under sigma (the median of an RMS:
    0.97 sigma measured) and doubles with it; any subset of query points measures the same."""
    rng = np.random.default_rng(0)
    uv, unit = rng.random((5000, 2)), rng.normal(0.0, 1.0, 5000)
    noise = {sigma: np.median(point_noise(np.c_[uv, sigma * unit])) for sigma in (0.002, 0.004)}
    assert 0.0016 < noise[0.002] < 0.002
    assert abs(noise[0.004] / noise[0.002] - 2) < 0.1
    subset = np.median(point_noise(np.c_[uv, 0.002 * unit], np.arange(0, 5000, 3)))
    assert abs(subset - noise[0.002]) < 0.0001


def test_a_noisy_sphere_takes_the_jet_everywhere():
    """A sphere is a quadric at every point: the K = 100 jet replaces (almost) every initial PCA K = 50 normal and
    the error falls to the jet's."""
    rng = np.random.default_rng(1)
    points = fibonacci_sphere(8000) + rng.normal(0.0, 0.005, (8000, 3))
    truth = fibonacci_sphere(8000)
    initial = pca_normals(points, 50)
    result = smooth_jet_normals(points, initial, 1.5)
    replaced = np.any(result != initial, axis=1)
    assert replaced.mean() > 0.9
    np.testing.assert_allclose(unoriented_angles(result[replaced], jet_normals(points, 100)[replaced]), 0, atol=1e-4)
    assert unoriented_angles(result, truth).mean() < 0.8 * unoriented_angles(initial, truth).mean()
    assert (np.einsum("ij,ij->i", result, initial) >= 0).all()  # on the initial normal's side


def test_a_cube_keeps_its_initial_normals_at_the_edges():
    """No quadric fits a neighbourhood that straddles an edge: there the initial (exact) normals stay as they are,
    while on the faces, away from the edges, the jet's normal takes over and is within a few degrees."""
    points, truth, initial = noisy_cube(20_000, noise=0.002)
    result = smooth_jet_normals(points, initial, 1.5)
    inside = np.clip(points, 0, 1)
    near = np.sort(np.minimum(inside, 1 - inside), axis=1)[:, 1]  # distance to the nearest edge, roughly
    edge, face = near < 0.03, near > 0.25
    assert edge.sum() > 1000 and face.sum() > 3000
    assert np.all(result[edge] == initial[edge], axis=1).mean() > 0.98
    assert np.any(result[face] != initial[face], axis=1).mean() > 0.9
    assert unoriented_angles(result[face], truth[face]).mean() < 1.0


def test_the_features_refine_the_smooth_jet_normals():
    """With smooth_jet set, the first normal of the features (the one Refine-Net corrects) is the smooth-point
    jet's, and the filtered normals average those; without it, the initial normals are used as given."""
    rng = np.random.default_rng(2)
    points = fibonacci_sphere(3000) + rng.normal(0.0, 0.005, (3000, 3))
    initial = pca_normals(points, 50)
    features = compute_features(points, initial, feature_config(smooth_jet=1.5))
    np.testing.assert_array_equal(features.n_first, smooth_jet_normals(points, initial, 1.5).astype(np.float32))
    plain = compute_features(points, initial, feature_config())
    np.testing.assert_array_equal(plain.n_first, initial.astype(np.float32))
    assert not np.array_equal(features.nf[:, 3:], plain.nf[:, 3:])

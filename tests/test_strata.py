"""Density matching: the relative noise of known noisy planes, the strata it asks for, and the shipped networks on a
cloud denser than its noise allows."""

from __future__ import annotations

import numpy as np
import pytest

from refinenet.cli.estimate import auto_strata, estimate_normals
from refinenet.data.noise import add_gaussian_noise
from refinenet.data.shapes import sample_shape
from refinenet.estimators.strata import consensus, consensus_k, relative_noise, strata, strata_needed
from refinenet.evaluation.metrics import unoriented_angles
from refinenet.geometry.scale import spacing_ratio
from refinenet.network.release import SHIPPED, load_release


def plane(n: int, noise: float) -> np.ndarray:
    """A unit square of n uniform points with Gaussian noise of `noise` percent of its diagonal."""
    points = np.c_[np.random.default_rng(0).random((n, 2)), np.zeros(n)]
    return add_gaussian_noise(points, noise, seed=1)


#: The spacing ratio of a 10k-point square: on such a square l_d is its diagonal, the unit of the noise.
RATIO = spacing_ratio(plane(10_000, 0.0))


def test_relative_noise_is_the_noise_in_percent_of_the_diagonal_at_the_training_density():
    assert relative_noise(plane(10_000, 0.0), RATIO) < 0.01
    assert relative_noise(plane(10_000, 0.3), RATIO) == pytest.approx(0.3, rel=0.1)


def test_relative_noise_grows_with_density_and_ignores_units():
    sparse, dense = relative_noise(plane(10_000, 0.3), RATIO), relative_noise(plane(40_000, 0.3), RATIO)
    assert dense > 1.5 * sparse  # four times the points: half the spacing (2x, less the jets' saturation)
    assert relative_noise(plane(10_000, 0.3) * 1000, RATIO) == pytest.approx(sparse, rel=1e-6)


def test_strata_split_the_rows_into_interleaved_subsets_of_equal_size():
    parts = strata(10, 3)
    assert [len(p) for p in parts] == [4, 3, 3]
    np.testing.assert_array_equal(np.sort(np.concatenate(parts)), np.arange(10))
    assert all(np.array_equal(a, b) for a, b in zip(parts, strata(10, 3), strict=True))


def test_strata_needed_halves_the_density_until_the_noise_is_within_the_limit():
    points = plane(40_000, 0.3)  # relative noise 0.48, 0.38 and 0.28 at 1, 2 and 4 strata
    assert strata_needed(points, RATIO, 0.5, 100) == 1
    assert strata_needed(points, RATIO, 0.35, 100) == 4
    assert strata_needed(points, RATIO, 0.35, 15_000) == 2  # 4 strata of 10k points are too small


def jittered(normals: np.ndarray, degrees: float, seed: int) -> np.ndarray:
    """Unit normals each tilted by about `degrees` at random, half of them flipped (estimators are unoriented)."""
    rng = np.random.default_rng(seed)
    tilted = normals + np.radians(degrees) * rng.standard_normal(normals.shape)
    tilted *= rng.choice([-1.0, 1.0], size=(len(normals), 1))
    return tilted / np.linalg.norm(tilted, axis=1, keepdims=True)


def dihedral(n: int) -> tuple[np.ndarray, np.ndarray]:
    """n points on two unit squares meeting at a right-angled edge (the floor z = 0 and the wall x = 0), with
    their faces' normals."""
    rng = np.random.default_rng(2)
    u, v = rng.random(n), rng.random(n)
    wall = np.arange(n) % 2 == 1
    points = np.c_[np.where(wall, 0.0, u), v, np.where(wall, u, 0.0)]
    return points, np.where(wall[:, None], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])


def test_consensus_averages_the_strata_and_keeps_sharp_edges():
    """Normals 10 deg off at random on a right-angled dihedral: the consensus of 8 strata (32 neighbours) brings
    the error down to about 10 / sqrt(32) deg, and the points next to the edge keep their own face's normal
    instead of the 45 deg mean of both faces."""
    points, truth = dihedral(20_000)
    noisy = jittered(truth, 10.0, seed=3)
    agreed = consensus(points, noisy, consensus_k(8))
    before, after = unoriented_angles(noisy, truth), unoriented_angles(agreed, truth)
    assert before.mean() == pytest.approx(12.5, rel=0.05)  # the mean of a 2-D Rayleigh of sigma 10 deg
    assert after.mean() < 0.25 * before.mean()
    edge = np.maximum(points[:, 0], points[:, 2]) < 0.01
    assert after[edge].mean() < 0.5 * before[edge].mean()


@pytest.fixture(scope="module")
def release():
    return load_release(SHIPPED)


def test_a_cloud_like_the_training_clouds_is_estimated_whole(release):
    points, _ = sample_shape("twistedstar_a", 10_000, seed=77)
    assert auto_strata(add_gaussian_noise(points, 0.1, seed=78), release, "refinenet", False) == 1


def test_strata_bring_a_dense_noisy_cloud_back_to_what_the_networks_know(release):
    """A CAD shape never trained on, with four times the training points and the largest test noise: whole, its
    patches are noisier than any training patch and Refine-Net is worse than at the training density."""
    points, truth = sample_shape("fandisk_a", 40_000, seed=77)
    points = add_gaussian_noise(points, 0.5, seed=78)
    n_strata = auto_strata(points, release, "refinenet", False)
    errors = {s: unoriented_angles(estimate_normals(points, release, n_strata=s), truth).mean() for s in (1, n_strata)}
    assert n_strata == 4  # at most 4: a stratum keeps the 10k points of a training cloud
    assert errors[n_strata] < 0.8 * errors[1], errors


def test_no_stratum_is_smaller_than_a_training_cloud(release):
    """However noisy, 20k points make at most 2 strata of the 10k points of a training cloud. (The floor is there
    for real scans: the street tile rue_madame_28's roughness is mostly geometry and hardly falls with its density,
    and without the floor its 125k points would make 64 strata.)"""
    points, _ = sample_shape("fandisk_a", 20_000, seed=77)
    assert auto_strata(add_gaussian_noise(points, 2.0, seed=78), release, "refinenet", False) == 2

"""Point patches (docs/algorithm.md §6): centring, scaling, rotation into the frame, ball subsets and padding."""

from __future__ import annotations

import numpy as np
import pytest

from refinenet.features.patches import point_patches
from refinenet.geometry.frames import normal_frames, to_local
from refinenet.geometry.neighbors import neighbour_lists


@pytest.fixture
def tilted_plane() -> tuple[np.ndarray, np.ndarray]:
    """2,000 random points on a plane through (1, 2, 3) with a random normal, and that normal repeated (nf, X = 2)."""
    rng = np.random.default_rng(0)
    normal = rng.normal(size=3)
    normal /= np.linalg.norm(normal)
    tangent = np.linalg.svd(normal[None])[2][1:]  # two unit vectors orthogonal to the normal
    points = rng.uniform(-1, 1, (2000, 2)) @ tangent + np.array([1.0, 2.0, 3.0])
    return points, np.tile(normal, (len(points), 2))


def test_knn_patch_of_a_plane_is_flat_in_the_frame_with_unit_radius(tilted_plane):
    points, nf = tilted_plane
    frames = normal_frames(nf)
    index = np.arange(0, 2000, 7)
    patches = point_patches(points, k=50, frames=frames[index], index=index)
    assert patches.shape == (len(index), 50, 3) and patches.dtype == np.float32
    np.testing.assert_allclose(patches[:, :, 2], 0.0, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(patches, axis=2).max(axis=1), 1.0, atol=1e-6)
    np.testing.assert_array_equal(patches[:, 0], 0.0)  # the point itself comes first, at the origin
    unrotated = point_patches(points, k=50, index=index)
    np.testing.assert_allclose(patches, to_local(frames[index], unrotated.astype(np.float64)), atol=1e-6)
    np.testing.assert_array_equal(point_patches(points, k=50)[index], unrotated)


def test_knn_patches_from_shared_lists_equal_those_of_their_own_query(tilted_plane):
    points, nf = tilted_plane
    index = np.arange(3, 2000, 11)
    frames = normal_frames(nf)[index]
    lists = neighbour_lists(points, 80)[index]
    np.testing.assert_array_equal(point_patches(points, k=50, frames=frames, index=index, neighbours=lists),
                                  point_patches(points, k=50, frames=frames, index=index))


def test_ball_patches_are_padded_subsets_within_the_radius(tilted_plane):
    points, _ = tilted_plane
    l_d = np.linalg.norm(points.max(0) - points.min(0))
    index = np.arange(0, 2000, 11)
    for radius, max_points in [(0.05, 300), (0.2, 40)]:  # balls smaller, then larger, than max_points
        patches = point_patches(points, mode="ball", radius=radius, max_points=max_points, index=index,
                                rng=np.random.default_rng(1))
        assert patches.shape == (len(index), max_points, 3)
        assert np.linalg.norm(patches, axis=2).max() <= 1.0 + 1e-6
        ball = np.linalg.norm(points[:, None] - points[index], axis=2) <= radius * l_d
        members = (np.linalg.norm(patches, axis=2) > 0).sum(axis=1)  # every member but the centre is non-zero
        size = ball.sum(axis=0)
        small = size <= max_points
        assert small.all() if max_points == 300 else not small.any()
        np.testing.assert_array_equal(members[small], size[small] - 1)  # the whole ball, then centre padding
        assert np.all(members[~small] >= max_points - 1)  # a subset, which may include the centre
        for patch in patches:  # no point is drawn twice
            nonzero = patch[np.linalg.norm(patch, axis=1) > 0]
            assert len(np.unique(nonzero, axis=0)) == len(nonzero)


def test_ball_subsets_are_deterministic_given_the_generator(tilted_plane):
    points, _ = tilted_plane
    draw = lambda seed: point_patches(points, mode="ball", radius=0.2, max_points=40,  # noqa: E731
                                      index=np.arange(50), rng=np.random.default_rng(seed))
    np.testing.assert_array_equal(draw(5), draw(5))
    assert not np.array_equal(draw(5), draw(6))


def test_unknown_mode_is_rejected(tilted_plane):
    with pytest.raises(ValueError, match="patch mode"):
        point_patches(tilted_plane[0], mode="grid")

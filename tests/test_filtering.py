"""Multi-scale bilateral filtering (docs/algorithm.md §3) on planes and dihedral edges with known normals."""

from __future__ import annotations

import numpy as np
import pytest

from refinenet.features.filtering import bilateral_filter
from refinenet.geometry.frames import target_sign

UP = np.array([0.0, 0.0, 1.0])


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _angles(normals: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Unoriented angles in degrees between rows of (N x X x 3) normals and (N x 3) truth."""
    cos = np.abs(np.einsum("nxi,ni->nx", normals, truth))
    return np.degrees(np.arccos(np.clip(cos, 0.0, 1.0)))


@pytest.fixture
def noisy_plane() -> tuple[np.ndarray, np.ndarray]:
    """A jittered 40 x 40 grid on z = 0 with noisy, randomly signed normals."""
    rng = np.random.default_rng(0)
    x, y = np.meshgrid(np.linspace(0, 1, 40), np.linspace(0, 1, 40))
    points = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1) + rng.normal(0, 0.003, (x.size, 3))
    normals = _unit(UP + rng.normal(0, 0.25, (x.size, 3))) * rng.choice([-1.0, 1.0], (x.size, 1))
    return points, normals


def test_plane_filtered_normals_are_closer_to_the_truth(noisy_plane):
    points, normals = noisy_plane
    nf = bilateral_filter(points, normals, r_f=0.08)
    assert nf.shape == (len(points), 27) and nf.dtype == np.float32
    angles = _angles(nf.reshape(len(points), 9, 3), np.tile(UP, (len(points), 1))).mean(axis=0)
    assert np.all(angles[1:] < angles[0])
    assert angles[-1] < 0.3 * angles[0]  # the widest kernels average most


def test_dihedral_edge_is_preserved_by_a_small_range_kernel():
    """A convex 90 degree edge: face A (z = 0, x < 0, normal +z) and face B (x = 0, z < 0, normal +x)."""
    s = np.linspace(-1, 0, 41)[:-1]  # the edge line itself is left out, so every point has one true normal
    y = np.linspace(0, 1, 41)
    s, y = (a.ravel() for a in np.meshgrid(s, y, indexing="ij"))
    zero = np.zeros_like(s)
    points = np.concatenate([np.stack([s, y, zero], axis=1), np.stack([zero, y, s], axis=1)])
    truth = np.repeat(np.eye(3)[[2, 0]], len(s), axis=0)
    nf = bilateral_filter(points, truth, r_f=0.05, sigma_s=(2.0,), sigma_r=(0.1, 2.0), include_initial=False)
    near_edge = np.abs(points[:, 0] + points[:, 2]) < 0.03
    angles = _angles(nf.reshape(len(points), 2, 3), truth)[near_edge]
    assert angles[:, 0].max() < 0.1  # sigma_r = 0.1: the other face has weight exp(-100)
    assert angles[:, 1].min() > 5.0  # sigma_r = 2: the faces blend


def test_output_does_not_depend_on_input_signs(noisy_plane):
    points, normals = noisy_plane
    signs = np.random.default_rng(1).choice([-1.0, 1.0], (len(points), 1))
    nf = bilateral_filter(points, normals)
    flipped = bilateral_filter(points, normals * signs)
    # Each filtered normal follows its own point's initial normal (f_i . n_i > 0) and is otherwise unchanged.
    np.testing.assert_array_equal(flipped, nf * np.repeat(signs, 27, axis=1).astype(np.float32))
    assert np.all(np.einsum("nxi,ni->nx", nf.reshape(-1, 9, 3)[:, 1:], normals) > 0)


def test_orient_with_gt_equals_clean_room_on_a_consistent_field(noisy_plane):
    points, normals = noisy_plane
    truth = np.tile(UP, (len(points), 1))
    # Within 45 degrees of the truth every pair of oriented normals has n_i . n_j > 0: nothing left to flip.
    consistent = _unit(UP + np.random.default_rng(3).normal(0, 0.1, points.shape))
    assert _angles(consistent[:, None], truth).max() < 45
    np.testing.assert_array_equal(bilateral_filter(points, consistent, orient_with_gt=truth),
                                  bilateral_filter(points, consistent))
    # With mixed signs the release orients the inputs first (its n0 column is the oriented normal) and then sums
    # without flipping, which differs from the clean-room result where oriented neighbours disagree.
    release = bilateral_filter(points, normals, orient_with_gt=truth)
    oriented = target_sign(normals, truth)
    np.testing.assert_allclose(release[:, :3], oriented, atol=1e-7)
    np.testing.assert_array_equal(release[:, 3:], bilateral_filter(points, oriented, orient_with_gt=truth)[:, 3:])
    assert not np.allclose(release[:, 3:], bilateral_filter(points, oriented)[:, 3:], atol=1e-3)


def test_one_entry_by_hand():
    """Order [n0, f(s1, r1..r4), f(s2, r1..r4)]; one entry recomputed from the formula of §3."""
    rng = np.random.default_rng(2)
    points = rng.uniform(0, 1, (12, 3))
    normals = _unit(rng.normal(size=(12, 3)))
    r_f, sigma_s, sigma_r = 0.4, (1.0, 2.0), (0.1, 0.2, 0.35, 0.5)
    radius = r_f * np.linalg.norm(points.max(0) - points.min(0))
    nf = bilateral_filter(points, normals, r_f=r_f, sigma_s=sigma_s, sigma_r=sigma_r)
    bare = bilateral_filter(points, normals, r_f=r_f, sigma_s=sigma_s, sigma_r=sigma_r, include_initial=False)
    np.testing.assert_array_equal(nf[:, 3:], bare)
    np.testing.assert_allclose(nf[:, :3], normals, atol=1e-7)
    for i in range(len(points)):
        for s, ss in enumerate(sigma_s):
            for r, sr in enumerate(sigma_r):
                total = np.zeros(3)
                for j in range(len(points)):
                    d = np.linalg.norm(points[i] - points[j])
                    if d <= radius:
                        cos = normals[i] @ normals[j]
                        w = np.exp(-d ** 2 / (ss * radius / 2) ** 2) * np.exp(-2 * (1 - abs(cos)) / (2 * sr ** 2))
                        total += w * np.sign(cos) * normals[j]
                column = 3 + 3 * (s * len(sigma_r) + r)
                np.testing.assert_allclose(nf[i, column:column + 3], _unit(total), atol=2e-6)

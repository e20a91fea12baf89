"""Per-point frames (docs/algorithm.md §4): orthonormality, sign rules, invariances and the local/world round trip."""

from __future__ import annotations

import numpy as np
import pytest

from refinenet.geometry.frames import normal_frames, target_sign, to_local, to_world


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@pytest.fixture
def field() -> np.ndarray:
    """nf (200 x 27): nine normals per point scattered around a random direction, signs aligned to n0."""
    rng = np.random.default_rng(0)
    centre = _unit(rng.normal(size=(200, 1, 3)))
    normals = _unit(centre + rng.normal(0, 0.3, (200, 9, 3)))
    normals = target_sign(normals, normals[:, :1])
    return normals.reshape(200, 27).astype(np.float32)


@pytest.mark.parametrize("mode", ["canonical", "faithful"])
def test_frames_are_orthonormal_with_e3_on_the_first_normal_side(field, mode):
    frames = normal_frames(field, mode)
    np.testing.assert_allclose(np.einsum("nji,njk->nik", frames, frames), np.broadcast_to(np.eye(3), frames.shape),
                               atol=1e-5)
    assert np.all(np.einsum("ni,ni->n", field[:, :3], frames[:, :, 2]) > 0)
    det = np.linalg.det(frames)
    if mode == "canonical":
        np.testing.assert_allclose(det, 1.0, atol=1e-6)
    else:
        np.testing.assert_allclose(np.abs(det), 1.0, atol=1e-5)


def test_columns_ascend_in_eigenvalue_and_faithful_matches_canonical_e3(field):
    canonical, faithful = normal_frames(field), normal_frames(field, "faithful")
    normals = field.reshape(len(field), -1, 3).astype(np.float64)
    tensor = np.einsum("nxi,nxj->nij", normals, normals)
    eigenvalues = np.einsum("nji,njk,nki->ni", canonical, tensor, canonical)
    assert np.all(np.diff(eigenvalues, axis=1) >= -1e-9)
    np.testing.assert_allclose(faithful[:, :, 2], canonical[:, :, 2], atol=1e-4)
    # Faithful keeps numpy's raw SVD signs: up to the e3 rule, exactly the reversed left singular vectors.
    raw = np.linalg.svd(field.reshape(len(field), -1, 3).transpose(0, 2, 1))[0][:, :, ::-1]
    sides = np.where(np.einsum("ni,ni->n", field[:, :3], raw[:, :, 2]) <= 0, -1.0, 1.0)
    np.testing.assert_array_equal(faithful, raw * sides[:, None, None])


def test_canonical_e2_sign_and_handedness(field):
    frames = normal_frames(field)
    normals = field.reshape(len(field), -1, 3)
    assert np.all(np.einsum("nxi,ni->n", normals, frames[:, :, 1]) >= 0)
    np.testing.assert_allclose(np.cross(frames[:, :, 1], frames[:, :, 2]), frames[:, :, 0], atol=1e-12)


def test_identical_normals_give_e3_equal_to_that_normal_and_the_tie_rule():
    rng = np.random.default_rng(1)
    n = _unit(rng.normal(size=(50, 3)))
    frames = normal_frames(np.tile(n, 9))
    np.testing.assert_allclose(frames[:, :, 2], n, atol=1e-12)
    e2 = frames[:, :, 1]
    # sum_x n_x . e2 = 0 exactly in theory: the largest-magnitude component of e2 decides its sign.
    assert np.all(np.take_along_axis(e2, np.abs(e2).argmax(axis=1)[:, None], axis=1) > 0)


def test_flipping_a_later_normal_keeps_e3_and_at_most_turns_the_frame_about_it(field):
    """T is sign-blind and e3 follows n_first, so only the e2 rule can react to flipping n_x (x >= 1)."""
    frames = normal_frames(field)
    rng = np.random.default_rng(2)
    flipped = field.reshape(len(field), 9, 3).copy()
    x = rng.integers(1, 9, len(field))
    flipped[np.arange(len(field)), x] *= -1
    after = normal_frames(flipped.reshape(len(field), 27))
    np.testing.assert_array_equal(after[:, :, 2], frames[:, :, 2])
    side = np.einsum("nxi,ni->n", flipped, frames[:, :, 1])
    same = side > 0
    assert same.any() and (~same).any()  # both cases occur in this field
    np.testing.assert_array_equal(after[same], frames[same])
    np.testing.assert_allclose(after[~same], frames[~same] * np.array([-1.0, -1.0, 1.0]), atol=1e-12)


def test_flipping_the_whole_field_mirrors_local_normals_in_x(field):
    normals = field.reshape(len(field), 9, 3).astype(np.float64)
    local = to_local(normal_frames(field), normals)
    mirrored = to_local(normal_frames(-field), -normals)
    np.testing.assert_allclose(mirrored, local * np.array([-1.0, 1.0, 1.0]), atol=1e-6)
    assert np.all(local[:, 0, 2] > 0)


def test_local_and_world_are_inverse(field):
    frames = normal_frames(field)
    rng = np.random.default_rng(3)
    v, stack = rng.normal(size=(len(field), 3)), rng.normal(size=(len(field), 100, 3))
    np.testing.assert_allclose(to_world(frames, to_local(frames, v)), v, atol=1e-12)
    np.testing.assert_allclose(to_world(frames, to_local(frames, stack)), stack, atol=1e-12)
    np.testing.assert_allclose(to_local(frames, frames[:, :, 2]), np.tile([0.0, 0.0, 1.0], (len(field), 1)),
                               atol=1e-12)
    np.testing.assert_allclose(to_local(frames, stack)[:, 7], to_local(frames, stack[:, 7]), atol=1e-12)


def test_target_sign():
    g = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    n0 = np.array([[0.0, 0.1, -1.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    np.testing.assert_array_equal(target_sign(g, n0), [[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def test_unknown_mode_is_rejected(field):
    with pytest.raises(ValueError, match="frame mode"):
        normal_frames(field, "lapack")

"""Height maps (docs/algorithm.md §7): planes, tilted planes and spheres with analytic heights, and a loop reference.

Axis convention under test: bin (r, c) sits at p_i + (r - 3) h u + (c - 3) h v with u = normalize(n_f x e2),
v = normalize(n_f x e1); for n_f = e3 of a det +1 frame that is u = -x', v = +y' (rows run along -x').
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from refinenet.features.heightmaps import bin_axes, height_maps
from refinenet.geometry.frames import normal_frames


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _tilted_lattice(theta: float, about_x: bool, h: float, q: int = 8) -> np.ndarray:
    """Points of the plane z = tan(theta) x (or y when about_x), on a lattice symmetric about the foot of every bin
    centre: spacing h cos(theta) / q along the slope, h / q across it, the origin included."""
    s = np.arange(-5 * q, 5 * q + 1) * h * np.cos(theta) / q
    t = np.arange(-5 * q, 5 * q + 1) * h / q
    s, t = (a.ravel() for a in np.meshgrid(s, t, indexing="ij"))
    slope = np.stack([np.cos(theta) * s, t, np.sin(theta) * s], axis=1)
    return slope[:, [1, 0, 2]] if about_x else slope


def test_no_points_give_no_maps():
    points = _tilted_lattice(0.0, False, 0.1)
    frames = np.broadcast_to(np.eye(3), (len(points), 3, 3))
    nf = np.tile([0.0, 0.0, 1.0, 1.0, 0.0, 0.0], (len(points), 1))
    assert height_maps(points, nf, frames, index=np.array([], dtype=np.int64)).shape == (0, 2, 7, 7)


@pytest.mark.parametrize("about_x", [False, True])
def test_tilted_plane_matches_the_analytic_heights(about_x):
    """A plane tilted by theta against n_f = e3: the ball of bin b meets it in a disc around the foot of b, so the
    weighted mean height is that of the foot, tan(theta) cos^2(theta) times b's in-plane offset (tan(theta) times
    the offset for small angles). Rows run along -x' and columns along +y'."""
    theta, rho = np.radians(10.0), 1.0
    points = _tilted_lattice(theta, about_x, rho / 3)
    centre = np.flatnonzero(np.all(points == 0, axis=1))
    frames = np.broadcast_to(np.eye(3), (len(points), 3, 3))
    nf = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    maps = height_maps(points, nf, frames, extent=rho, index=centre)[0, 0]
    offsets = np.arange(-3, 4) * rho / 3
    expected = np.sin(theta) * np.cos(theta) * offsets / rho
    expected = np.tile(expected, (7, 1)) if about_x else np.tile(-expected[:, None], (1, 7))
    np.testing.assert_allclose(maps, expected, atol=1e-6)
    # The same configuration under a proper rotation gives the same map: the grid is tied to the frame.
    rotation = Rotation.from_rotvec([0.3, -1.1, 0.7]).as_matrix()
    turned = height_maps(points @ rotation.T, nf @ rotation.T, rotation @ frames, extent=rho, index=centre)
    np.testing.assert_allclose(turned[0, 0], expected, atol=1e-6)


def test_flat_plane_gives_zero_maps():
    rng = np.random.default_rng(0)
    normal = _unit(rng.normal(size=3))
    tangent = np.linalg.svd(normal[None])[2][1:]
    points = rng.uniform(-1, 1, (3000, 2)) @ tangent + 5.0
    nf = np.tile(normal, (len(points), 2))
    maps = height_maps(points, nf, normal_frames(nf), k=60, index=np.arange(0, 3000, 13))
    assert maps.shape == (231, 2, 7, 7) and maps.dtype == np.float32
    np.testing.assert_allclose(maps, 0.0, atol=1e-6)


def test_sphere_follows_the_sagitta():
    """Outward normal at the pole of a unit sphere: the surface falls below the tangent plane by 1 - sqrt(1 - d^2)
    at in-plane distance d (bins far from the pole average over a ball, hence the tolerance)."""
    golden = np.pi * (3.0 - np.sqrt(5.0))
    z = np.linspace(1.0, np.cos(0.6), 12000)
    phi = golden * np.arange(len(z))
    rxy = np.sqrt(1.0 - z ** 2)
    points = np.stack([rxy * np.cos(phi), rxy * np.sin(phi), z], axis=1)
    nf = np.repeat(points, 2, axis=0).reshape(len(points), 6)
    rho = 0.15
    maps = height_maps(points, nf, normal_frames(nf), extent=rho, index=np.array([0]))[0]
    offsets = np.arange(-3, 4) * rho / 3
    d2 = offsets[:, None] ** 2 + offsets[None, :] ** 2
    expected = -(1.0 - np.sqrt(1.0 - d2)) / rho
    np.testing.assert_allclose(maps[0], expected, atol=0.01)
    assert np.all(maps[0][d2 > 0] < 0)
    np.testing.assert_allclose(maps[0], maps[0][::-1, ::-1], atol=0.01)  # radially symmetric


def _reference(points: np.ndarray, nf: np.ndarray, frames: np.ndarray, index: np.ndarray, k: int, m: int):
    """One ball query per bin, straight from §7."""
    tree = cKDTree(points)
    half = m // 2
    out = np.zeros((len(index), nf.shape[1] // 3, m, m))
    for row, i in enumerate(index):
        rho = tree.query(points[i], k=k)[0][-1]
        h = rho / half
        for f, n in enumerate(_unit(nf[i].reshape(-1, 3))):
            e1, e2 = frames[i, :, 0], frames[i, :, 1]
            u, v = np.cross(n, e2), np.cross(n, e1)
            v = v / np.linalg.norm(v) if np.linalg.norm(v) > 1e-12 else None
            u = u / np.linalg.norm(u) if np.linalg.norm(u) > 1e-12 else np.cross(n, v)
            v = v if v is not None else np.cross(u, n)
            for r in range(m):
                for c in range(m):
                    b = points[i] + (r - half) * h * u + (c - half) * h * v
                    near = tree.query_ball_point(b, 0.9 * h)
                    if not near or (r == c == half and len(near) == 1):
                        continue
                    d = points[near] - b
                    w = np.exp(-np.sum(d * d, axis=1) / (2 * h * h))
                    out[row, f, r, c] = (w @ (d @ n)) / w.sum() / rho
    return out


@pytest.mark.parametrize("m", [7, 5])
def test_vectorised_equals_loop_reference(m):
    """A noisy sphere with random normals (skewed grids), normals along e1 or e2 (fallback axes) or in the
    e1 e2 plane (u = -v, a grid collapsed onto a line), and a subset index."""
    rng = np.random.default_rng(1)
    points = _unit(rng.normal(size=(500, 3))) + rng.normal(0, 0.02, (500, 3))
    nf = np.repeat(_unit(points), 3, axis=0).reshape(500, 9) + rng.normal(0, 0.1, (500, 9))
    nf[:40, 3:] = _unit(rng.normal(size=(40, 2, 3))).reshape(40, 6)  # far from e3: skewed grids
    frames = normal_frames(nf)
    nf[40:45, 6:9] = frames[40:45, :, 1]  # n_f = e2: u falls back
    nf[45:50, 6:9] = -frames[45:50, :, 0]  # n_f = -e1: v falls back
    nf[50:55, 6:9] = _unit(frames[50:55, :, 0] + frames[50:55, :, 1])  # n_f in the e1 e2 plane: u = -v
    index = np.concatenate([np.arange(0, 60, 2), rng.choice(500, 10, replace=False)])
    u, v = bin_axes(_unit(nf[index].reshape(len(index), 3, 3)), frames[index])
    cos = np.abs(np.einsum("nxi,nxi->nx", u, v))
    assert np.any((cos > 0.5) & (cos < 0.99)) and np.any(cos == 1.0)  # skewed and collapsed grids
    maps = height_maps(points, nf, frames, m=m, k=30, index=index)
    np.testing.assert_allclose(maps, _reference(points, nf, frames, index, 30, m), atol=1e-6)
    np.testing.assert_array_equal(maps, height_maps(points, nf, frames, m=m, k=30)[index])


def test_bin_axes_regular_and_degenerate():
    frames = np.broadcast_to(np.eye(3), (3, 3, 3))
    normals = np.array([[[0.0, 0.0, 1.0]], [[0.0, 1.0, 0.0]], [[-1.0, 0.0, 0.0]]])
    u, v = bin_axes(normals, frames)
    np.testing.assert_allclose(u[0, 0], [-1.0, 0.0, 0.0])
    np.testing.assert_allclose(v[0, 0], [0.0, 1.0, 0.0])
    for a, b, n in zip(u[:, 0], v[:, 0], normals[:, 0], strict=True):  # (v, u, n_f) right-handed, orthonormal
        np.testing.assert_allclose(np.cross(b, a), n, atol=1e-12)

"""Simulated range scans against shapes whose answers are known in closed form: a sphere (what it shows, and the
noise along each ray) and a torus (which hides parts of itself from every viewpoint)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from settings import SCANNER

from refinenet.data.scans import simulate_scan, viewpoints
from refinenet.errors import ParamsError

#: params.yaml's Kinect v1 at 3x its pixel, so that a test samples about 100,000 surface points, not 900,000.
COARSE = replace(SCANNER, pixel_rad=3 * SCANNER.pixel_rad)
EXACT = replace(COARSE, sigma_m=0.0, disparity_step=0.0)
#: torus_a: major radius 1, minor 0.35, scaled so that its farthest point is at distance 1.
TORUS_R, TORUS_r = 1 / 1.35, 0.35 / 1.35


def _rays(points: np.ndarray, view: np.ndarray, sensor) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each return's sensor position, unit ray direction and measured range (shape units)."""
    origin = viewpoints(sensor)[view]
    offset = points - origin
    ranges = np.linalg.norm(offset, axis=1)
    return origin, offset / ranges[:, None], ranges


def _sphere_range(origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Where each ray first meets the unit sphere."""
    b = np.einsum("ij,ij->i", origin, direction)
    return -b - np.sqrt(b**2 - (np.einsum("ij,ij->i", origin, origin) - 1))


def test_returns_face_their_sensor_with_exact_unit_normals():
    points, normals, view = simulate_scan("sphere_a", COARSE, seed=3)
    origin, direction, _ = _rays(points, view, COARSE)
    assert np.abs(np.linalg.norm(normals, axis=1) - 1).max() < 1e-12
    assert (np.einsum("ij,ij->i", normals, direction) < 0).all()
    np.testing.assert_allclose(normals, points / np.linalg.norm(points, axis=1, keepdims=True), atol=0.05)
    assert set(view.tolist()) == set(range(COARSE.views))


def test_a_sphere_shows_the_rays_its_silhouette_covers():
    """One return per pixel of the sphere's disk on the image plane, of radius tan(asin(1/d)): at least the pixels
    wholly inside it, at most those it touches (the density falls with range: the grid is angular)."""
    points, _, view = simulate_scan("sphere_a", EXACT, seed=4)
    radius = np.tan(np.arcsin(EXACT.object_radius_m / EXACT.range_m)) / EXACT.pixel_rad  # in pixels
    corners = np.arange(-int(radius) - 2, int(radius) + 3)
    x0, y0 = np.meshgrid(corners[:-1], corners[:-1], indexing="ij")  # each pixel's lower corner
    far = np.hypot(np.maximum(np.abs(x0), np.abs(x0 + 1)), np.maximum(np.abs(y0), np.abs(y0 + 1)))
    near = np.hypot(np.clip(0, x0, x0 + 1), np.clip(0, y0, y0 + 1))
    inside, touched = int((far < radius).sum()), int((near < radius).sum())
    counts = np.bincount(view, minlength=EXACT.views)
    assert ((inside <= counts) & (counts <= touched)).all(), (inside, counts, touched)


def test_range_noise_grows_with_the_square_of_the_range():
    """The measured range minus the true range along each ray, over sigma_m r^2: a standard normal."""
    sensor = replace(COARSE, disparity_step=0.0)
    points, _, view = simulate_scan("sphere_a", sensor, seed=5)
    origin, direction, ranges = _rays(points, view, sensor)
    true = _sphere_range(origin, direction)
    metres = sensor.object_radius_m
    z = (ranges - true) * metres / (sensor.sigma_m * (true * metres) ** 2)
    assert abs(z.mean()) < 0.05 and z.std() == pytest.approx(1.0, abs=0.05)


def test_ranges_are_quantised_in_disparity():
    sensor = replace(COARSE, sigma_m=0.0)
    points, _, view = simulate_scan("sphere_a", sensor, seed=6)
    disparity = 1 / (_rays(points, view, sensor)[2] * sensor.object_radius_m) / sensor.disparity_step
    np.testing.assert_allclose(disparity, np.round(disparity), atol=1e-6)
    steps = np.diff(np.unique(np.round(disparity)))
    assert (steps == 1).mean() > 0.9  # consecutive levels: depth steps of about step * r^2


def test_every_return_is_the_first_surface_its_ray_meets():
    """On a torus seen from 20 degrees above, the near side of the tube hides parts of the far side and of the
    hole: march each ray through the torus's implicit function and find its first crossing."""
    points, _, view = simulate_scan("torus_a", EXACT, seed=7)
    origin, direction, ranges = _rays(points, view, EXACT)
    first = np.concatenate([_first_crossing(origin[rows], direction[rows], ranges[rows] + 0.05)
                            for rows in np.array_split(np.arange(len(points)), 20)])
    hidden = first < ranges - 0.01  # the tube is 0.5 thick: a hidden return lies far behind the first crossing
    assert hidden.sum() == 0, f"{hidden.sum()} of {len(ranges)} returns lie behind a nearer surface"
    assert len(points) > 1000


def _first_crossing(origin: np.ndarray, direction: np.ndarray, length: np.ndarray, steps: int = 2000) -> np.ndarray:
    """The first distance along each ray, up to `length`, that lies inside the torus (inf: none)."""
    t = np.linspace(0, 1, steps)[None, :] * length[:, None]
    q = origin[:, None, :] + t[..., None] * direction[:, None, :]
    inside = (np.sum(q**2, axis=2) + TORUS_R**2 - TORUS_r**2) ** 2 < 4 * TORUS_R**2 * np.sum(q[..., :2] ** 2, axis=2)
    return np.where(inside.any(axis=1), t[np.arange(len(t)), np.argmax(inside, axis=1)], np.inf)


def test_a_scan_is_reproducible():
    a, b = simulate_scan("gear_a", COARSE, seed=8), simulate_scan("gear_a", COARSE, seed=8)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)


def test_a_shape_outside_the_catalogue_is_refused_by_its_key():
    with pytest.raises(ParamsError, match="scanner.shapes: 'teapot' is not a shape of the catalogue"):
        simulate_scan("teapot", COARSE, seed=0)


def test_a_sensor_that_sees_too_little_of_the_shape_is_refused_by_its_key():
    with pytest.raises(ParamsError, match="scanner: the shape spans about .* rays of the sensor, fewer than 1000"):
        simulate_scan("sphere_a", replace(COARSE, range_m=500.0), seed=0)

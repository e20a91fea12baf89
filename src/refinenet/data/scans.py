"""Simulated range scans of the procedural shapes: what a depth camera sees of an object (docs/algorithm.md §1.5).

A virtual sensor at a few viewpoints around the shape casts rays on a regular grid of its image plane. Each ray
returns the nearest surface point facing the sensor (self-occlusion by a z-buffer over a dense sample of the
surface), so the density falls with the square of the range and with the obliquity of the surface, and parts
hidden from every viewpoint are missing. The range is measured with Gaussian noise along the ray that grows with
the square of the range, and quantised as a Kinect v1 quantises it (the disparity 1/r in fixed steps, so depth
steps grow with the square of the range too). The normals are the exact normals of the surface points hit.
"""

from __future__ import annotations

import numpy as np

from refinenet.config import ScannerConfig
from refinenet.data import shapes
from refinenet.errors import ParamsError

#: Surface samples per ray, at least, on the nearest surface seen square-on (more where it is farther or oblique):
#: a ray misses the front surface, and may see an occluded one through the gap, with probability exp(-8) or less.
SAMPLES_PER_RAY = 8.0
#: The fewest rays a shape may span (its area over the nearest footprint): a scan of fewer has too few points for
#: any estimator's neighbourhood.
MIN_RETURNS = 1000


def viewpoints(sensor: ScannerConfig) -> np.ndarray:
    """(views, 3) sensor positions in shape units, evenly spaced in azimuth at the sensor's elevation."""
    distance = sensor.range_m / sensor.object_radius_m
    azimuth = 2 * np.pi * np.arange(sensor.views) / sensor.views
    elevation = np.radians(sensor.elevation_deg)
    return distance * np.c_[np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth),
                            np.full(sensor.views, np.sin(elevation))]


def check_shapes(names: tuple[str, ...]) -> None:
    """Every scanned shape is one of the catalogue's, or a one-line error under its key."""
    unknown = [name for name in names if name not in shapes.catalogue()]
    if unknown:
        raise ParamsError("scanner.shapes", f"'{unknown[0]}' is not a shape of the catalogue (data.shapes)")


def simulate_scan(shape: str, sensor: ScannerConfig, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The points, exact unit normals and viewpoint index of every ray's return, over all viewpoints, in the
    shape's units. The same (shape, sensor, seed) gives bit-identical arrays."""
    check_shapes((shape,))
    positions = viewpoints(sensor)
    nearest = np.linalg.norm(positions[0]) - 1.0  # range of the closest possible surface point, in shape radii
    footprint = nearest * sensor.pixel_rad
    area = shapes.surface(shape).areas.sum()
    samples = int(SAMPLES_PER_RAY * area / footprint**2)
    if samples < SAMPLES_PER_RAY * MIN_RETURNS:
        raise ParamsError("scanner", f"the shape spans about {samples / SAMPLES_PER_RAY:.0f} rays of the sensor, "
                                     f"fewer than {MIN_RETURNS}: bring it nearer or make the pixels finer")
    surface, normals = shapes.sample_shape(shape, samples, seed)
    rng = np.random.default_rng(seed + 1)
    parts = [_view(surface, normals, position, sensor, rng) for position in positions]
    points = np.concatenate([p for p, _ in parts])
    hit_normals = np.concatenate([n for _, n in parts])
    view = np.concatenate([np.full(len(p), i) for i, (p, _) in enumerate(parts)])
    return points, hit_normals, view


def _view(surface: np.ndarray, normals: np.ndarray, position: np.ndarray, sensor: ScannerConfig,
          rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The returns of one viewpoint: the nearest front-facing sample per ray, noisy and quantised in range."""
    forward = -position / np.linalg.norm(position)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    rays = surface - position
    facing = np.einsum("ij,ij->i", normals, rays) < 0
    rays, hit_normals = rays[facing], normals[facing]
    depth = rays @ forward
    pixel = np.floor(np.c_[rays @ right, rays @ up] / depth[:, None] / sensor.pixel_rad).astype(np.int64)
    ranges = np.linalg.norm(rays, axis=1)
    order = np.lexsort((ranges, pixel[:, 1], pixel[:, 0]))
    first = order[np.r_[True, np.any(np.diff(pixel[order], axis=0) != 0, axis=1)]]
    metres = sensor.object_radius_m
    measured = ranges[first] * metres
    measured = measured + rng.normal(size=len(first)) * sensor.sigma_m * measured**2
    if sensor.disparity_step > 0:
        measured = 1.0 / (np.round(1.0 / measured / sensor.disparity_step) * sensor.disparity_step)
    directions = rays[first] / ranges[first][:, None]
    return position + directions * (measured / metres)[:, None], hit_normals[first]


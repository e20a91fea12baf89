"""Orthographic point splats with a depth test: the renderer of the normal and error figures (fig:syn, fig:insight).

Each point is drawn as a disc a few pixels wide, and a pixel keeps the colour of the nearest disc covering it, so
the far side of a shape never shows through its front. Plain numpy and deterministic (the nearest-last order is a
stable sort): 100k points render in well under a second, with no display and no OpenGL.
"""

from __future__ import annotations

import numpy as np

#: The fixed view of every figure: azimuth and elevation in degrees.
AZIMUTH, ELEVATION = 35.0, 25.0


def view_rotation(azimuth: float = AZIMUTH, elevation: float = ELEVATION) -> np.ndarray:
    """(3, 3) rows: the camera's right, up and towards-the-viewer axes in world coordinates (z up)."""
    a, e = np.radians(azimuth), np.radians(elevation)
    towards = np.array([np.cos(e) * np.sin(a), -np.cos(e) * np.cos(a), np.sin(e)])
    right = np.cross([0.0, 0.0, 1.0], towards)
    right /= np.linalg.norm(right)
    return np.stack([right, np.cross(towards, right), towards])


def scan_view(points: np.ndarray) -> np.ndarray:
    """A view of a real scan, whose up axis is not known: along its least-spread principal axis (a range scan's
    depth), from the side of the coordinate origin, where a scanner that records in its own frame stands; up is
    the first of the world axes z, y, x that is not near that direction (at most two can be)."""
    centred = points - points.mean(axis=0)
    _, axes = np.linalg.eigh(centred.T @ centred)
    towards = axes[:, 0] * (-1.0 if axes[:, 0] @ points.mean(axis=0) > 0 else 1.0)
    up = next(axis for axis in np.eye(3)[[2, 1, 0]] if abs(axis @ towards) < 0.8)
    up = up - (up @ towards) * towards
    up /= np.linalg.norm(up)
    return np.stack([np.cross(up, towards), up, towards])


def facing(normals: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """Unoriented normals flipped to face the viewer, so that normal colours do not depend on their sign."""
    flip = np.where(normals @ rotation[2] < 0, -1.0, 1.0)
    return normals * flip[:, None]


def normal_colours(normals: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """(N, 3) RGB in [0, 1]: the viewer-facing normal's world components mapped from [-1, 1]."""
    return (facing(normals, rotation) + 1.0) / 2.0


def splat_radius(n_points: int, size: int) -> int:
    """Disc radius in pixels that closes the gaps between neighbouring points of a surface seen whole: about half
    their spacing on screen, from 1 pixel (100k points in 300) to 6 (sparse clouds)."""
    return int(np.clip(round(0.5 * size / np.sqrt(max(n_points, 1))), 1, 6))


def splat(points: np.ndarray, colours: np.ndarray, rotation: np.ndarray, size: int = 400, radius: int | None = None,
          margin: int = 6) -> np.ndarray:
    """(size, size, 3) float image on white: the cloud seen along -rotation[2], fitted to the square; `radius`
    defaults to `splat_radius`."""
    radius = splat_radius(len(points), size) if radius is None else radius
    camera = (points - points.mean(axis=0)) @ rotation.T
    low, high = camera[:, :2].min(axis=0), camera[:, :2].max(axis=0)
    scale = (size - 1 - 2 * (margin + radius)) / max(float((high - low).max()), 1e-12)
    centre = (size - 1) / 2 - scale * (high - low) / 2
    u = np.rint(centre[0] + scale * (camera[:, 0] - low[0])).astype(np.int64)
    v = np.rint(size - 1 - centre[1] - scale * (camera[:, 1] - low[1])).astype(np.int64)
    dy, dx = np.mgrid[-radius:radius + 1, -radius:radius + 1]
    disc = dx * dx + dy * dy <= radius * radius + radius  # a round disc, not a diamond, at small radii
    dx, dy = dx[disc], dy[disc]
    order = np.argsort(camera[:, 2], kind="stable")  # far first: the nearest disc is written last and kept
    pu, pv = u[order, None] + dx, v[order, None] + dy
    inside = (pu >= 0) & (pu < size) & (pv >= 0) & (pv < size)
    pixels = (pv * size + pu)[inside]
    image = np.ones((size * size, 3))
    image[pixels] = np.broadcast_to(colours[order, None, :], (*pu.shape, 3))[inside]
    return image.reshape(size, size, 3)

"""Small analytic clouds with exact normals, shared by several test modules."""

import numpy as np


def fibonacci_sphere(n: int, radius: float = 1.0) -> np.ndarray:
    """Near-uniform points on a sphere, deterministic (exact normals: p / |p|)."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5**0.5) * i
    return radius * np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=1)

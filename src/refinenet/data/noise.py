"""Noise synthesis (docs/algorithm.md §1.2) and the per-job seeds that make every cloud reproducible."""

from __future__ import annotations

import hashlib

import numpy as np


def bbox_diagonal(points: np.ndarray) -> float:
    """l_d = ||max(P) - min(P)||, the length unit of every radius and noise level in the paper."""
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def derive_seed(global_seed: int, *names: object) -> int:
    """A 32-bit seed from the global seed and a job's wildcards, independent of job order and Python's hash salt."""
    text = "/".join([str(global_seed), *map(str, names)])
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:4], "little")


def add_gaussian_noise(points: np.ndarray, percent: float, seed: int) -> np.ndarray:
    """Isotropic i.i.d. Gaussian noise on each coordinate with sigma = percent/100 x l_d of the clean cloud."""
    if percent < 0:
        raise ValueError(f"noise level must be >= 0 percent, got {percent}")
    sigma = percent / 100.0 * bbox_diagonal(points)
    rng = np.random.default_rng(seed)
    return points + rng.normal(0.0, sigma, size=points.shape)

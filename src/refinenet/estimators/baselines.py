"""Classical normal estimators used as baselines in the paper's tables: PCA and Jet (degree-2 fitting).

Both return unit, unoriented normals (N x 3). Neighbourhoods are kNN with the point itself included.
"""

from __future__ import annotations

import numpy as np

from refinenet.config import BaselineConfig
from refinenet.data.shapes import BIG_NOISE
from refinenet.geometry.neighbors import build_tree, chunks, covariances, knn, knn_covariances, smallest_eigenvectors
from refinenet.threads import thread_map

METHODS = ("pca", "jet")


def neighbourhood_size(config: BaselineConfig, method: str, category: str | None) -> int:
    """K of `method` on a cloud of `category` (None: unknown): the paper uses a larger K on BigNoise clouds."""
    if category == BIG_NOISE:
        return config.big_noise_k
    return config.pca_k if method == "pca" else config.jet_k


def baseline_normals(points: np.ndarray, method: str, config: BaselineConfig, category: str | None) -> np.ndarray:
    """Normals of `method` (pca or jet) with the paper's neighbourhood for the cloud's category."""
    return fit_normals(points, method, neighbourhood_size(config, method, category), config.jet_degree)


def fit_normals(points: np.ndarray, method: str, k: int, degree: int = 2) -> np.ndarray:
    """Normals of `method` (pca, or a jet of `degree`) fitted to the k nearest neighbours of every point."""
    if method == "pca":
        return pca_normals(points, k)
    if method == "jet":
        return jet_normals(points, k, degree)
    raise ValueError(f"unknown baseline '{method}' (one of {METHODS})")


def pca_normals(points: np.ndarray, k: int) -> np.ndarray:
    """Normal = eigenvector of the smallest eigenvalue of the k-neighbourhood covariance (Hoppe et al. 1992)."""
    return smallest_eigenvectors(knn_covariances(points, k))[1]


def _monomials(x: np.ndarray, y: np.ndarray, degree: int) -> np.ndarray:
    """Columns x^i y^j with i + j <= degree, ordered by total degree (1, x, y, x^2, xy, y^2, ...)."""
    cols = [x ** (d - j) * y ** j for d in range(degree + 1) for j in range(d + 1)]
    return np.stack(cols, axis=-1)


def jet_normals(points: np.ndarray, k: int, degree: int = 2) -> np.ndarray:
    """Normal of an osculating jet (Cazals & Pouget 2005): a least-squares height function of `degree`."""
    points = np.asarray(points, dtype=np.float64)
    return jet_fit(points, knn(points, k, tree=build_tree(points))[1], degree)[0]


def jet_fit(points: np.ndarray, idx: np.ndarray, degree: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Normals (M, 3) and RMS height residuals (M,), in the cloud's units, of the jets of the neighbourhoods
    `points[idx]` (M, k), each taken at its first point (the query point of a kNN list).

    Each neighbourhood is expressed in its PCA frame centred on the query point, scaled to unit size, and
    fitted with z = sum a_ij x^i y^j; the normal at the origin is (-a_x, -a_y, 1) mapped back to world. The
    residual's squares are divided by k minus the number of coefficients (at least 1; an exact fit has none), so
    that on a noisy plane it estimates the noise's standard deviation. Chunks of neighbourhoods are fitted on
    `native_threads` threads.
    """
    n_coef = (degree + 1) * (degree + 2) // 2
    m, k = idx.shape
    if k < n_coef:
        raise ValueError(f"jet of degree {degree} needs k >= {n_coef} neighbours, got k = {k}")
    _, covs = covariances(points, idx)
    _, frames = np.linalg.eigh(covs)  # columns: normal-like axis first, then the two tangent axes
    normals, residuals = np.empty((m, 3)), np.empty(m)

    def fit(sl: slice) -> None:
        local = points[idx[sl]] - points[idx[sl, 0], None, :]
        uvw = np.einsum("nkj,nji->nki", local, frames[sl])  # coordinates along (e1, e2, e3)
        scale = np.linalg.norm(uvw, axis=2).max(axis=1)[:, None]
        scale[scale == 0] = 1.0
        z, x, y = (uvw[:, :, 0] / scale, uvw[:, :, 1] / scale, uvw[:, :, 2] / scale)
        a = _monomials(x, y, degree)
        ata = np.einsum("nki,nkj->nij", a, a)
        atz = np.einsum("nki,nk->ni", a, z)
        coef = np.linalg.solve(ata + 1e-12 * np.eye(n_coef), atz[..., None])[..., 0]
        local_normal = np.stack([np.ones(len(coef)), -coef[:, 1], -coef[:, 2]], axis=1)
        world = np.einsum("nij,nj->ni", frames[sl], local_normal)
        normals[sl] = world / np.linalg.norm(world, axis=1, keepdims=True)
        heights = z - np.einsum("nki,ni->nk", a, coef)
        residuals[sl] = scale[:, 0] * np.sqrt((heights ** 2).sum(axis=1) / max(k - n_coef, 1))

    thread_map(fit, chunks(m, k))
    return normals, residuals

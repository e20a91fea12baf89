"""Classical normal estimators used as baselines in the paper's tables: PCA and Jet (degree-2 fitting).

Both return unit, unoriented normals (N x 3). Neighbourhoods are kNN with the point itself included.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from refinenet.config import BaselineConfig
from refinenet.data.shapes import BIG_NOISE
from refinenet.geometry.neighbors import build_tree, chunks, covariances, first_neighbours, knn, pca_normals
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


def fit_normals(points: np.ndarray, method: str, k: int, degree: int = 2,
                neighbours: np.ndarray | None = None) -> np.ndarray:
    """Normals of `method` (pca, or a jet of `degree`) fitted to the k nearest neighbours of every point. A jet
    takes them from `neighbours`, the points' kNN lists, when shared (PCA sums its neighbourhoods on a grid)."""
    if method == "pca":
        return pca_normals(points, k)
    if method == "jet":
        return jet_normals(points, k, degree, neighbours)
    raise ValueError(f"unknown baseline '{method}' (one of {METHODS})")


def jet_normals(points: np.ndarray, k: int, degree: int = 2, neighbours: np.ndarray | None = None) -> np.ndarray:
    """Normal of an osculating jet (Cazals & Pouget 2005): a least-squares height function of `degree`."""
    points = np.asarray(points, dtype=np.float64)
    idx = knn(points, k, tree=build_tree(points))[1] if neighbours is None else first_neighbours(neighbours, k)
    return jet_fit(points, idx, degree)[0]


def jet_fit(points: np.ndarray, idx: np.ndarray, degree: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Normals (M, 3) and RMS height residuals (M,), in the cloud's units, of the jets of the neighbourhoods
    `points[idx]` (M, k), each taken at its first point (the query point of a kNN list).

    Each neighbourhood is expressed in its PCA frame centred on the query point, scaled to unit size, and
    fitted with z = sum a_ij x^i y^j; the normal at the origin is (-a_x, -a_y, 1) mapped back to world. The
    residual's squares are divided by k minus the number of coefficients (at least 1; an exact fit has none), so
    that on a noisy plane it estimates the noise's standard deviation. Chunks of neighbourhoods are fitted on
    `native_threads` threads, by a kernel that holds one neighbourhood's normal equations at a time.
    """
    n_coef = (degree + 1) * (degree + 2) // 2
    m, k = idx.shape
    if k < n_coef:
        raise ValueError(f"jet of degree {degree} needs k >= {n_coef} neighbours, got k = {k}")
    points = np.ascontiguousarray(points, dtype=np.float64)
    idx = np.ascontiguousarray(idx, dtype=np.int64)
    _, covs = covariances(points, idx)
    _, frames = np.linalg.eigh(covs)  # columns: normal-like axis first, then the two tangent axes
    normals, residuals = np.empty((m, 3)), np.empty(m)
    thread_map(lambda sl: _fit_jets(points, idx[sl], frames[sl], degree, normals[sl], residuals[sl]), chunks(m, k))
    return normals, residuals


@njit(nogil=True, cache=True)
def _fit_jets(points, idx, frames, degree, normals, residuals):
    """`jet_fit` of each row of idx with its frame, into normals and residuals: the least-squares fit by the
    normal equations (A^T A + 1e-12 I) c = A^T z, A's columns the monomials x^i y^j, i + j <= degree, ordered
    by total degree (1, x, y, x^2, xy, y^2, ...)."""
    m, k = idx.shape
    n_coef = (degree + 1) * (degree + 2) // 2
    uvw = np.empty((k, 3))
    a = np.empty((k, n_coef))
    ata = np.empty((n_coef, n_coef))
    atz = np.empty(n_coef)
    for row in range(m):
        f = frames[row]
        q = idx[row, 0]
        scale = 0.0
        for j in range(k):
            p = idx[row, j]
            d0, d1, d2 = points[p, 0] - points[q, 0], points[p, 1] - points[q, 1], points[p, 2] - points[q, 2]
            for c in range(3):
                uvw[j, c] = d0 * f[0, c] + d1 * f[1, c] + d2 * f[2, c]
            scale = max(scale, np.sqrt(uvw[j, 0] ** 2 + uvw[j, 1] ** 2 + uvw[j, 2] ** 2))
        if scale == 0.0:
            scale = 1.0
        ata[:] = 0.0
        atz[:] = 0.0
        for j in range(k):
            _monomials(uvw[j, 1] / scale, uvw[j, 2] / scale, degree, a[j])
            z = uvw[j, 0] / scale
            for r in range(n_coef):
                atz[r] += a[j, r] * z
                for c in range(n_coef):
                    ata[r, c] += a[j, r] * a[j, c]
        for r in range(n_coef):
            ata[r, r] += 1e-12
        _solve(ata, atz)
        coef = atz
        w0 = f[0, 0] - coef[1] * f[0, 1] - coef[2] * f[0, 2]
        w1 = f[1, 0] - coef[1] * f[1, 1] - coef[2] * f[1, 2]
        w2 = f[2, 0] - coef[1] * f[2, 1] - coef[2] * f[2, 2]
        length = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
        normals[row, 0], normals[row, 1], normals[row, 2] = w0 / length, w1 / length, w2 / length
        squares = 0.0
        for j in range(k):
            height = uvw[j, 0] / scale
            for c in range(n_coef):
                height -= a[j, c] * coef[c]
            squares += height * height
        residuals[row] = scale * np.sqrt(squares / max(k - n_coef, 1))


@njit(nogil=True, cache=True)
def _monomials(x, y, degree, out):
    """out = x^i y^j with i + j <= degree, ordered by total degree (1, x, y, x^2, xy, y^2, ...)."""
    column = 0
    for total in range(degree + 1):
        for j in range(total + 1):
            out[column] = x ** (total - j) * y ** j
            column += 1


@njit(nogil=True, cache=True)
def _solve(matrix, rhs):
    """rhs = matrix^-1 rhs by Gaussian elimination with partial pivoting (LAPACK's gesv), both overwritten: one
    small system per neighbourhood, without the allocations of np.linalg.solve."""
    n = len(rhs)
    for col in range(n):
        pivot = col
        for r in range(col + 1, n):
            if abs(matrix[r, col]) > abs(matrix[pivot, col]):
                pivot = r
        if pivot != col:
            for c in range(n):
                matrix[col, c], matrix[pivot, c] = matrix[pivot, c], matrix[col, c]
            rhs[col], rhs[pivot] = rhs[pivot], rhs[col]
        for r in range(col + 1, n):
            factor = matrix[r, col] / matrix[col, col]
            for c in range(col + 1, n):
                matrix[r, c] -= factor * matrix[col, c]
            rhs[r] -= factor * rhs[col]
    for r in range(n - 1, -1, -1):
        total = rhs[r]
        for c in range(r + 1, n):
            total -= matrix[r, c] * rhs[c]
        rhs[r] = total / matrix[r, r]

"""Slow, literal MFPS (docs/algorithm.md §2): plain loops over points, patches and trials, float64 throughout.

It exists only to check the vectorised `refinenet.estimators.mfps`. It shares two pieces with it: the random draws
(`trial_indices`, so both see the same trials) and the L1 trend filter (tested on its own in test_mfps.py).
Everything else is re-derived from the spec, line by line.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from refinenet.estimators.mfps import SIGMA_FLOOR, MFPSConfig, l1_trend_filter, trial_indices


def _pca(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centroid, ascending eigenvalues and eigenvector of the smallest one of the covariance (divided by k)."""
    mu = pts.mean(axis=0)
    w, v = np.linalg.eigh((pts - mu).T @ (pts - mu) / len(pts))
    return mu, w, v[:, 0]


def reference_threshold(s: np.ndarray, config: MFPSConfig) -> float:
    """A.1 steps 3-5 with the spec's 1-based bins."""
    bins = config.hist_bins
    hist = np.zeros(bins + 1)  # hist[b], b = 1..bins
    for value in s:
        for b in range(1, bins + 1):
            if (b - 1) / bins <= value < b / bins:
                hist[b] += 1
    b_star = 1 + int(np.argmax(hist[1:]))
    x = np.r_[np.nan, l1_trend_filter(hist[1:] / hist[b_star], config.tv_lambda)]
    for b in range(b_star + 1, bins):
        if x[b - 1] - x[b + 1] < config.flat_tol and x[b] < x[b_star] - config.drop_tol:
            return b / bins
    for b in range(b_star + 1, bins + 1):
        if x[b] < x[b_star] - config.drop_tol:
            return b / bins
    return 1.0


def reference_bandwidth(points: np.ndarray, knn: np.ndarray, k0: int, k_bw: int) -> np.ndarray:
    """A.2: residual voting over all k0-patches, then the mean over kNN_{k_bw}."""
    n = len(points)
    best, err = np.full(n, 1e9), np.zeros(n)
    for c in range(n):
        patch = knn[c, :k0]
        mu, _, u = _pca(points[patch])
        r = [abs((points[j] - mu) @ u) for j in patch]
        e_c = sum(r) + 1e-9
        t_c = e_c / k0
        for j, r_cj in zip(patch, r, strict=True):
            h = abs((points[j] - points[c]) @ u)
            with np.errstate(over="ignore"):
                cost = e_c * np.exp((h / (2 * t_c)) ** 2)
            if cost < best[j]:
                best[j], err[j] = cost, r_cj
    return np.array([err[knn[i, :k_bw]].mean() for i in range(n)])


def reference_mfps(points: np.ndarray, config: MFPSConfig, simple: bool = False) -> np.ndarray:
    """MFPS normals by the letter of docs/algorithm.md §2 (same seed -> same trials as the vectorised code); `simple`:
    those of the simple-MFPS ablation (the highest-scoring patch)."""
    points = np.asarray(points, dtype=np.float64)
    n = len(points)
    k0, k_max, k_bw = config.k0, config.scales[-1], config.k_bw
    knn = cKDTree(points).query(points, max(k_max, k_bw))[1]

    # A.1
    centroid, normal, s = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n)
    for i in range(n):
        centroid[i], w, normal[i] = _pca(points[knn[i, :k0]])
        w = np.clip(w, 0, None)
        s[i] = w[0] / w.sum()
    s /= s.max()
    candidate = s > reference_threshold(s, config)

    # A.2
    l_d = np.linalg.norm(points.max(axis=0) - points.min(axis=0))
    sigma = np.maximum(reference_bandwidth(points, knn, k0, k_bw), SIGMA_FLOOR * l_d)

    # A.3 + A.4
    kk = np.asarray(config.scales, dtype=float)
    if config.eta == "code":
        eta = np.exp(-(((1 - kk / kk.max()) / 3) ** 2))
    else:
        eta = config.beta + (1 - config.beta) * (kk - kk.min()) / (kk.max() - kk.min())
    registered: dict[int, list[tuple[float, np.ndarray, np.ndarray]]] = {c: [] for c in np.flatnonzero(candidate)}
    for k, eta_k in zip(config.scales, eta, strict=True):
        for i in range(n):
            patch = knn[i, :k]
            if not candidate[patch].any():
                continue
            q = points[patch]
            tau = 2 * sigma[i]
            draws = trial_indices(config.seed, k, np.array([i]), config.trials)[0]
            best_score, plane = 0.0, None
            for pick in draws:
                m, _, nn = _pca(np.vstack([q[0], q[pick]]))
                if ((points[i] - m) @ nn) ** 2 > tau**2:
                    continue
                score = sum(math.exp(-(((x - m) @ nn) ** 2) / tau**2) for x in q)
                if score > best_score:
                    best_score, plane = score, (m, nn)
            if plane is None:
                m, _, nn = _pca(q)
                plane = (m, nn)
            m, nn = plane
            for c in patch:
                if candidate[c]:
                    e_c = sum(math.exp(-(((x - m) @ nn) ** 2) / (2 * sigma[c]) ** 2) for x in q) / k
                    registered[c].append((e_c * eta_k, m, nn))

    # A.5
    normals = normal.copy()
    for c, patches in registered.items():
        ranked = sorted(patches, key=lambda t: -t[0])  # stable: ties keep registration order
        if simple:
            normals[c] = ranked[0][2]
            continue
        p_c, neighbourhood = points[c], points[knn[c, :k0]]
        members: list[tuple[np.ndarray, np.ndarray]] = []
        for _, m, nn in ranked:
            p_ref = p_c + ((m - p_c) @ nn) * nn
            if sum((x - p_ref) @ nn for x in neighbourhood) >= 0:
                nn = -nn
            if all(math.degrees(math.acos(min(1.0, abs(nn @ a)))) > config.theta_t for a, _ in members):
                members.append((nn, p_ref))
                if len(members) == config.a_max:
                    break
        normals[c] = min(members, key=lambda t: t[0] @ (t[1] - p_c))[0]
    return normals

"""Stage A: multi-scale fitting patch selection (MFPS), the initial normals of Refine-Net (docs/algorithm.md §2).

Smooth points keep their PCA normal. A near-feature "candidate" point takes the normal of one fitting patch,
chosen among every patch of every scale that contains it: each patch is fitted with the best of R random planes
(the centre plus three random neighbours), scored for consistency with the candidate, and an anisotropic rule
then prefers the face the candidate lies on over the faces it is merely close to.

Where the paper [P] and the release [C] disagree, `MFPSConfig` makes the choice explicit; defaults follow the
recommendations of docs/algorithm.md §2 A.7 (paper scales and angle, release estimator).

Speed: only patches that contain a candidate are fitted. The R trials of a chunk of patches are batched arrays:
closed-form 3x3 eigenvectors and an R x k residual matrix per patch, searched in float32, after which the
winning plane is refitted in float64. Chunks run on a thread pool. Randomness is counter-based (a hash of seed,
scale, centre and trial), so the output is bit-identical for any chunk size or thread count, and a plain-loop
reference (tests/mfps_reference.py) can reproduce the exact draws.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterable, Iterator
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass

import numpy as np
from scipy.optimize import lsq_linear
from tqdm import tqdm

from refinenet.config import MFPSConfig
from refinenet.data.io import check_array
from refinenet.data.noise import bbox_diagonal
from refinenet.geometry.neighbors import (
    chunks,
    covariances,
    first_neighbours,
    knn,
    neighbour_lists,
    smallest_eigenvectors,
)
from refinenet.profiling import stage
from refinenet.threads import thread_map

#: The two methods of the step: MFPS and its "simple MFPS" ablation, both from one set of fitted patches.
METHODS = ("mfps", "simple_mfps")
#: Elements of the R x k float32 residual matrix per chunk of patches (16 MB). On two threads chunks of 4 MB took
#: 1.15x the time of these, 64 MB 1.12x (the whole of MFPS on 100k points; each thread waits less for the GIL
#: between fewer, larger numpy calls); on one thread the size hardly matters.
PATCH_CHUNK_ELEMENTS = 1 << 22

#: Lower bound of the residual bandwidth, as a fraction of the bounding-box diagonal. Only noise-free planar
#: regions reach it (their residuals are exactly 0); the gate and the kernels need a positive width there.
SIGMA_FLOOR = 1e-6

#: Bits of the per-trial hash given to each of the three neighbour draws (3 x 21 <= 64).
_DRAW_BITS = 21
_GOLDEN = 0x9E3779B97F4A7C15


# --------------------------------------------------------------------------------------------------- A.1

def raw_variation(eigenvalues: np.ndarray) -> np.ndarray:
    """l1 / (l1 + l2 + l3) per point (eigenvalues of the k0-patch covariance, ascending)."""
    lam = np.clip(eigenvalues, 0.0, None)
    total = lam.sum(axis=1)
    return np.divide(lam[:, 0], total, out=np.zeros(len(lam)), where=total > 0)


def surface_variation(eigenvalues: np.ndarray) -> np.ndarray:
    """s = l1 / (l1 + l2 + l3) per point, divided by its global maximum so that s lies in [0, 1]."""
    raw = raw_variation(eigenvalues)
    return _normalised(raw, raw.max(initial=0.0))


def _normalised(raw: np.ndarray, top: float) -> np.ndarray:
    return raw / top if top > 0 else raw


@dataclass(frozen=True)
class Candidacy:
    """The two whole-cloud statistics of A.1: the largest raw surface variation and the threshold tau_s on the
    normalised one. A tile of a large cloud takes them from the whole cloud (`cloud_candidacy`), so that a point
    is a candidate in its tile exactly when it is one in the whole cloud."""

    top: float
    threshold: float

    def candidates(self, raw: np.ndarray) -> np.ndarray:
        """Whether each point of `raw` (its `raw_variation`) is a near-feature candidate: tau_s < s."""
        return _normalised(raw, self.top) > self.threshold


def cloud_candidacy(raw: np.ndarray, config: MFPSConfig) -> Candidacy:
    """Candidacy of a cloud from the `raw_variation` of all its points."""
    top = float(raw.max(initial=0.0))
    return Candidacy(top, variation_threshold(_normalised(raw, top), config))


def point_variation(points: np.ndarray, config: MFPSConfig, index: np.ndarray) -> np.ndarray:
    """raw_variation of points[index] over their k0 nearest neighbours in `points`."""
    neighbours = knn(points, config.k0, query=points[index], with_distances=False, index_dtype=np.int32)[1]
    return raw_variation(smallest_eigenvectors(covariances(points, neighbours)[1])[0])


def l1_trend_filter(y: np.ndarray, lam: float) -> np.ndarray:
    """argmin_x 1/2 ||y - x||^2 + lam ||Dx||_1 (D: first differences), solved exactly through its dual.

    The dual is a bounded least-squares problem, min ||y - D^T z|| with |z| <= lam, which the active-set
    solver BVLS finishes exactly in a few steps; then x = y - D^T z. This replaces [C]'s CVX call.
    """
    y = np.asarray(y, dtype=np.float64)
    if lam == 0 or len(y) < 2:
        return y.copy()
    n = len(y)
    dt = np.zeros((n, n - 1))
    dt[np.arange(n - 1), np.arange(n - 1)] = -1.0
    dt[np.arange(1, n), np.arange(n - 1)] = 1.0
    z = lsq_linear(dt, y, bounds=(-lam, lam), method="bvls").x
    return y - dt @ z


def knee_threshold(x: np.ndarray, peak: int, flat_tol: float, drop_tol: float) -> float:
    """Threshold tau_s = b / bins at the first bin b after the peak where the filtered histogram x has
    flattened and dropped well below the peak (0-based `peak`; docs/algorithm.md §2 A.1 step 5).

    Fallbacks ([C] would crash): the first bin after the peak that has dropped; failing that 1 (no candidates).
    """
    bins = len(x)
    low = x[peak] - drop_tol
    for j in range(peak + 1, bins - 1):
        if x[j - 1] - x[j + 1] < flat_tol and x[j] < low:
            return (j + 1) / bins
    for j in range(peak + 1, bins):
        if x[j] < low:
            return (j + 1) / bins
    return 1.0


def variation_threshold(variation: np.ndarray, config: MFPSConfig) -> float:
    """tau_s from the histogram of surface variation, smoothed by L1 trend filtering (A.1 steps 3-5)."""
    bins = config.hist_bins
    b = np.floor(variation * bins).astype(np.int64)
    counts = np.bincount(b[(b >= 0) & (b < bins)], minlength=bins).astype(np.float64)
    peak = int(np.argmax(counts))
    if counts[peak] == 0:
        return 1.0
    x = l1_trend_filter(counts / counts[peak], config.tv_lambda)
    return knee_threshold(x, peak, config.flat_tol, config.drop_tol)


# --------------------------------------------------------------------------------------------------- A.2

def residual_bandwidth(points: np.ndarray, neighbours: np.ndarray, centroids: np.ndarray,
                       normals: np.ndarray, smoothing: np.ndarray) -> np.ndarray:
    """sigma_i: residuals voted from the best-fitting k0-patch, averaged over kNN_{k_bw} (A.2).

    `neighbours` (N, k0) and `smoothing` (N, k_bw) are kNN lists; `centroids`/`normals` the PCA planes of the
    k0-patches. Every point j keeps the PCA residual r_cj of the patch c minimising E_c exp((h_cj / 2t_c)^2);
    as in [C]'s loop, which keeps the first strictly smaller cost, ties go to the lowest c.
    """
    n, k0 = neighbours.shape
    coords = np.ascontiguousarray(points.T)
    best, err = np.full(n, 1e9), np.zeros(n)
    for sl in chunks(n, k0):  # patches c in increasing order
        nb = neighbours[sl].astype(np.intp)
        u = normals[sl]
        h = np.einsum("ibk,bi->bk", np.take(coords, nb, axis=1) - points[sl].T[:, :, None], u)
        r = np.abs(h - np.einsum("bi,bi->b", centroids[sl] - points[sl], u)[:, None])
        h = np.abs(h)  # distance to the plane moved through the patch centre p_c
        e = r.sum(axis=1) + 1e-9
        with np.errstate(over="ignore"):
            cost = (e[:, None] * np.exp(np.square(h * (k0 / (2.0 * e))[:, None]))).ravel()
        j = nb.ravel()
        low = np.full(n, np.inf)
        np.minimum.at(low, j, cost)
        win = np.flatnonzero(cost == low[j])
        first = np.full(n, len(cost))
        np.minimum.at(first, j[win], win)
        better = np.flatnonzero(low < best)
        best[better], err[better] = low[better], r.ravel()[first[better]]
    sigma = np.empty(n)
    for sl in chunks(n, smoothing.shape[1]):
        sigma[sl] = np.take(err, smoothing[sl]).mean(axis=1)
    return sigma


# --------------------------------------------------------------------------------------------------- A.3

def _splitmix64(x: np.ndarray) -> np.ndarray:
    """The SplitMix64 finaliser: a bijective 64-bit mix, so hashing counters gives independent draws."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def trial_indices(seed: int, k: int, centres: np.ndarray, trials: int) -> np.ndarray:
    """Positions (len(centres), trials, 3) of 3 distinct neighbours drawn uniformly from Q[1..k-1] per trial.

    The draw of trial r of the patch (centre i, scale k) is a hash of (seed, k, i, r) alone (SplitMix64
    output number i*R + r of a stream keyed by seed and k), so it does not depend on how patches are batched.
    One 64-bit hash gives three 21-bit uniforms, mapped to ranges k-1, k-2, k-3 by multiply-shift (a bias
    below k / 2^21) and made distinct by skipping the positions already drawn.
    """
    with np.errstate(over="ignore"):
        key = _splitmix64(np.array([seed], dtype=np.uint64) * np.uint64(_GOLDEN) + np.uint64(k))
        counter = (np.asarray(centres, dtype=np.uint64)[:, None] * np.uint64(trials)
                   + np.arange(trials, dtype=np.uint64)[None, :])
        h = _splitmix64(key + (counter + np.uint64(1)) * np.uint64(_GOLDEN))
    mask = np.uint64((1 << _DRAW_BITS) - 1)
    shift = np.uint64(_DRAW_BITS)

    def uniform(bits: np.ndarray, n: int) -> np.ndarray:
        return ((bits & mask) * np.uint64(n) >> shift).astype(np.int64)

    m = k - 1
    a = uniform(h >> np.uint64(43), m)
    b = uniform(h >> np.uint64(22), m - 1)
    c = uniform(h >> np.uint64(1), m - 2)
    b += b >= a
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    c += c >= lo
    c += c >= hi
    return np.stack([a, b, c], axis=-1) + 1


def smallest_eigenvectors_3x3(c00: np.ndarray, c01: np.ndarray, c02: np.ndarray, c11: np.ndarray,
                              c12: np.ndarray, c22: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Components of the unit eigenvector of the smallest eigenvalue of symmetric PSD 3x3 matrices.

    Closed form, because np.linalg.eigh is far slower on millions of tiny matrices: the smallest eigenvalue
    l1 from the trigonometric solution of the characteristic cubic, then the largest column of the adjugate
    of C - l1 I (the cross products of its rows). Works in the inputs' precision (float32 or float64). When
    l1 is numerically a double eigenvalue, every direction orthogonal to the remaining eigenvector is a
    solution, and one of them is returned.
    """
    trace = c00 + c11 + c22  # >= every |entry| of a PSD matrix: dividing by it keeps float32 in range
    unit = 1.0 / np.where(trace > 0, trace, 1.0)
    c00, c01, c02, c11, c12, c22 = (c * unit for c in (c00, c01, c02, c11, c12, c22))
    q = (c00 + c11 + c22) / 3.0
    b00, b11, b22 = c00 - q, c11 - q, c22 - q
    p = np.sqrt((b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * (c01 * c01 + c02 * c02 + c12 * c12)) / 6.0)
    det = b00 * (b11 * b22 - c12 * c12) - c01 * (c01 * b22 - c12 * c02) + c02 * (c01 * c12 - b11 * c02)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(p > 0, np.clip(det / (2.0 * p * p * p), -1.0, 1.0), 0.0)
    lam = q + 2.0 * p * np.cos(np.arccos(r) / 3.0 + 2.0 * np.pi / 3.0)
    m00, m11, m22 = c00 - lam, c11 - lam, c22 - lam
    a00, a11, a22 = m11 * m22 - c12 * c12, m00 * m22 - c02 * c02, m00 * m11 - c01 * c01
    a01, a02, a12 = c02 * c12 - c01 * m22, c01 * c12 - c02 * m11, c01 * c02 - m00 * c12
    # adj(C - l1 I) = (l2 - l1)(l3 - l1) e1 e1^T: its largest column is the one with the largest diagonal.
    first = (a00 >= a11) & (a00 >= a22)
    second = ~first & (a11 >= a22)
    cols = ((a00, a01, a02), (a01, a11, a12), (a02, a12, a22))
    n = [np.where(first, cols[0][i], np.where(second, cols[1][i], cols[2][i])) for i in range(3)]
    norm2 = n[0] * n[0] + n[1] * n[1] + n[2] * n[2]
    degenerate = norm2 <= np.square(64.0 * np.finfo(norm2.dtype).eps)
    if degenerate.any():
        rows = np.stack([np.stack([m00, c01, c02], -1), np.stack([c01, m11, c12], -1),
                         np.stack([c02, c12, m22], -1)], axis=-2)[degenerate]
        fallback = _orthogonal_unit(rows)
        for i in range(3):
            n[i][degenerate] = fallback[:, i]
        norm2[degenerate] = 1.0
    inv = 1.0 / np.sqrt(norm2)
    return n[0] * inv, n[1] * inv, n[2] * inv


def _orthogonal_unit(rows: np.ndarray) -> np.ndarray:
    """A unit vector orthogonal to the largest row of each (M, 3, 3) stack (any vector if all rows vanish)."""
    largest = rows[np.arange(len(rows)), np.argmax(np.square(rows).sum(-1), axis=-1)]
    v = np.cross(largest, np.eye(3)[np.argmin(np.abs(largest), axis=-1)])
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(norm > 0, v / np.where(norm > 0, norm, 1.0), np.array([0.0, 0.0, 1.0]))


@dataclass
class PatchFits:
    """Planes of the fitted patches of one scale, and the (patch, candidate) pairs of S_c with their E_c."""

    centres: np.ndarray
    """(P,) patch centres i (point indices)."""
    m: np.ndarray
    """(P, 3) a point of the plane: the centroid of the best 4-point trial (or of Q when all are rejected)."""
    n: np.ndarray
    """(P, 3) unit plane normals (unoriented)."""
    pair_patch: np.ndarray
    """(S,) int32 row into the arrays above."""
    pair_candidate: np.ndarray
    """(S,) int32 candidate c contained in that patch (point index)."""
    pair_consistency: np.ndarray
    """(S,) float32 E_c(patch), before the scale weight eta(k)."""


def fit_patches(points: np.ndarray, neighbours: np.ndarray, centres: np.ndarray, sigma: np.ndarray,
                candidate: np.ndarray, trials: int, seed: int, workers: int = 1,
                on_chunk: Callable[[int], None] | None = None, ids: np.ndarray | None = None) -> PatchFits:
    """Best-of-R random plane of each patch Q = kNN_k(i), i in `centres` (A.3), and E_c for every candidate
    c in Q (A.4). `neighbours` is (N, k): the scale is its width. `sigma` must be positive. `ids` name the
    points in the trial hash (default: their positions), so a tile draws the trials of the whole cloud."""
    k = neighbours.shape[1]
    step = max(1, PATCH_CHUNK_ELEMENTS // (trials * k))
    coords = np.ascontiguousarray(points.T)

    def run(sl: slice) -> tuple[np.ndarray, ...]:
        result = _fit_chunk(coords, neighbours, centres[sl], sigma, candidate, trials, seed,
                            centres[sl] if ids is None else ids[centres[sl]])
        if on_chunk is not None:
            on_chunk(sl.stop - sl.start)
        return result

    slices = [slice(s, min(s + step, len(centres))) for s in range(0, len(centres), step)]
    parts = thread_map(run, slices, workers)
    offsets = np.cumsum([0] + [len(p[0]) for p in parts[:-1]], dtype=np.int32)
    return PatchFits(
        centres=centres,
        m=_concat([p[0] for p in parts], (0, 3), np.float64),
        n=_concat([p[1] for p in parts], (0, 3), np.float64),
        pair_patch=_concat([p[2] + o for p, o in zip(parts, offsets, strict=True)], (0,), np.int32),
        pair_candidate=_concat([p[3] for p in parts], (0,), np.int32),
        pair_consistency=_concat([p[4] for p in parts], (0,), np.float32),
    )


def _fit_chunk(coords: np.ndarray, neighbours: np.ndarray, centres: np.ndarray, sigma: np.ndarray,
               candidate: np.ndarray, trials: int, seed: int, keys: np.ndarray) -> tuple[np.ndarray, ...]:
    """One batch of patches, from the cloud's coordinates as (3, N); every result row depends on its own
    patch only, so results do not depend on the chunking. Arrays are laid out by component, (3, b, ...)."""
    nb = neighbours[centres]
    b, k = nb.shape
    origin = coords[:, centres]
    q = np.take(coords, nb, axis=1) - origin[:, :, None]  # (3, b, k): each patch centred on its p_i, so p_i = 0
    tau = 2.0 * sigma[centres][:, None]

    # Search the R trials in float32, in units of tau: the 4-point LS planes through the centre (the origin)
    # and 3 random neighbours, as (3, b, R), and their scores sum_q exp(-((q - m).n / tau)^2), from one
    # (R x 4)(4 x k) product per patch. Only the winner's plane is refitted in float64.
    draws = trial_indices(seed, k, keys, trials) + (np.arange(b) * k)[:, None, None]
    scaled = (q / tau).astype(np.float32).reshape(3, b * k)
    m, n = _four_point_planes(np.take(scaled, draws.transpose(2, 0, 1), axis=1))
    d = np.einsum("ibr,ibr->br", m, n)  # the plane is {y : y.n = d}; the centre lies |d| tau from it
    accepted = d * d <= 1.0
    homogeneous = np.ones((b, 4, k), dtype=np.float32)
    homogeneous[:, :3] = scaled.reshape(3, b, k).transpose(1, 0, 2)
    res = np.matmul(np.concatenate([n, -d[None]]).transpose(1, 2, 0).copy(), homogeneous)
    np.square(res, out=res)
    np.negative(res, out=res)
    np.exp(res, out=res)
    score = res.sum(axis=-1)
    score[~accepted] = -1.0
    rows = np.arange(b)
    best = draws[rows, np.argmax(score, axis=1)]  # the first maximum, as a loop keeping strictly better ones
    plane_m, plane_n = (x.T for x in _four_point_planes(np.take(q.reshape(3, b * k), best.T, axis=1)))
    rejected = ~accepted.any(axis=1)
    if rejected.any():  # [C] would reuse the previous patch's plane; fall back to the PCA plane of Q
        pts = q[:, rejected].transpose(1, 2, 0).reshape(-1, 3)
        mu, c = covariances(pts, np.arange(len(pts)).reshape(-1, k))
        plane_m[rejected], plane_n[rejected] = mu, smallest_eigenvectors(c)[1]

    # Consistency E_c = mean_q exp(-((q - m).n)^2 / (2 sigma_c)^2) for each candidate c in Q.
    r = np.einsum("ibk,bi->bk", q, plane_n) - np.einsum("bi,bi->b", plane_m, plane_n)[:, None]
    pb, pq = np.nonzero(candidate[nb])
    cand = nb[pb, pq]
    kernel = np.square(r).astype(np.float32)[pb]
    kernel *= (-1.0 / np.square(2.0 * sigma[cand])).astype(np.float32)[:, None]
    np.exp(kernel, out=kernel)
    consistency = kernel.sum(axis=1) / np.float32(k)
    return plane_m + origin.T, plane_n, pb.astype(np.int32), cand.astype(np.int32), consistency


def _four_point_planes(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centroids and unit normals (3, ...) of the LS planes through the origin and three points x (3, 3, ...)."""
    m = (x[:, 0] + x[:, 1] + x[:, 2]) / 4.0
    dev = [x[:, j] - m for j in range(3)] + [-m]  # the 4 points about their centroid
    cov = [sum(v[i] * v[j] for v in dev) for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))]
    return m, np.stack(smallest_eigenvectors_3x3(*cov))


def _concat(parts: Iterable[np.ndarray], empty_shape: tuple[int, ...], dtype: type) -> np.ndarray:
    parts = list(parts)
    return np.concatenate(parts) if parts else np.zeros(empty_shape, dtype=dtype)


# --------------------------------------------------------------------------------------------------- A.4

def eta_weights(scales: tuple[int, ...], form: str, beta: float = 0.9) -> np.ndarray:
    """Scale weights eta(k) of the consistency score D = E eta(k): [C]'s exponential or [P]'s linear form."""
    k = np.asarray(scales, dtype=np.float64)
    if form == "code":
        return np.exp(-np.square((1.0 - k / k.max()) / 3.0))
    if form == "paper":
        span = k.max() - k.min()
        return beta + (1.0 - beta) * (k - k.min()) / span if span > 0 else np.ones_like(k)
    raise ValueError(f"eta form must be 'code' or 'paper', got {form!r}")


# --------------------------------------------------------------------------------------------------- A.5

def select_fitting_patches(points: np.ndarray, centroids: np.ndarray, candidates: np.ndarray,
                           pair_candidate: np.ndarray, pair_patch: np.ndarray, pair_score: np.ndarray,
                           plane_m: np.ndarray, plane_n: np.ndarray, theta_t: float,
                           a_max: int) -> tuple[np.ndarray, np.ndarray]:
    """Normals (len(candidates), 3) of each candidate from its registered patches S_c (A.5): MFPS's, and simple
    MFPS's ([P] §Ablation: the highest-scoring patch, no anisotropic set), which is A's first member and so free.

    Pair s registers patch pair_patch[s] (plane (plane_m, plane_n)) with score D = pair_score[s] for
    candidate pair_candidate[s]; pairs come in registration order, which breaks ties in D. `centroids` are
    the k0-neighbourhood centroids, because the orientation sum is sum_{q in N_c} (q - p_ref).n =
    k0 (qbar_c - m).n. A takes, in decreasing D, each plane more than theta_t (unoriented) from all members
    so far, up to a_max members; the member whose oriented plane has the smallest offset n.(m - p_c) wins.
    """
    n_pairs = len(pair_candidate)
    dense = np.full(len(points), -1, dtype=np.int32)
    dense[candidates] = np.arange(len(candidates), dtype=np.int32)
    owner = dense[pair_candidate]
    cos_t = math.cos(math.radians(theta_t))
    usable = np.ones(n_pairs, dtype=bool)
    members: list[np.ndarray] = []  # per candidate, the patch of each member of A (-1: none)
    for round_ in range(a_max):
        key = np.where(usable, pair_score, -np.inf)
        top = np.full(len(candidates), -np.inf)
        np.maximum.at(top, owner, key)
        win = np.flatnonzero(usable & (key == top[owner]))
        first = np.full(len(candidates), n_pairs)
        np.minimum.at(first, owner[win], win)
        found = first < n_pairs
        if not found.any():
            break
        member = np.where(found, pair_patch[np.minimum(first, n_pairs - 1)], -1)
        members.append(member)
        if round_ + 1 < a_max:  # planes within theta_t of the new member can no longer join A
            member_n = plane_n[member]
            for sl in chunks(n_pairs, 3):
                dots = np.einsum("sd,sd->s", np.take(plane_n, pair_patch[sl], axis=0),
                                 np.take(member_n, owner[sl], axis=0))
                usable[sl] &= np.abs(dots) < cos_t
    p_c, qbar = points[candidates], centroids[candidates]
    offsets, normals = [], []
    for member in members:
        m, n = plane_m[member], plane_n[member]
        n = np.where((np.einsum("cd,cd->c", qbar - m, n) >= 0)[:, None], -n, n)
        offsets.append(np.where(member >= 0, np.einsum("cd,cd->c", n, m - p_c), np.inf))
        normals.append(n)
    choice = np.argmin(np.stack(offsets), axis=0)
    return np.stack(normals)[choice, np.arange(len(candidates))], plane_n[members[0]]


# --------------------------------------------------------------------------------------------------- all

def mfps_normals(points: np.ndarray, config: MFPSConfig, progress: bool = False,
                 workers: int | None = None, stats: dict[str, int] | None = None,
                 length: float | None = None, ids: np.ndarray | None = None,
                 candidacy: Candidacy | None = None, neighbours: np.ndarray | None = None) -> np.ndarray:
    """Unit, unoriented MFPS normals (N, 3) of a cloud (docs/algorithm.md §2); the arguments are
    `mfps_and_simple_normals`'s."""
    return mfps_and_simple_normals(points, config, progress, workers, stats, length, ids, candidacy,
                                   neighbours)["mfps"]


def mfps_and_simple_normals(points: np.ndarray, config: MFPSConfig, progress: bool = False,
                            workers: int | None = None, stats: dict[str, int] | None = None,
                            length: float | None = None, ids: np.ndarray | None = None,
                            candidacy: Candidacy | None = None,
                            neighbours: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Unit, unoriented normals (N, 3) of a cloud by each of METHODS: MFPS (docs/algorithm.md §2) and its simple-MFPS
    ablation, which differ only in the last step (A.5), so one pass fits the patches for both.

    `workers` threads fit the patches (default: the cores this process may use); the result does not
    depend on it. `progress` shows a bar per step, and each step is a `profiling.stage`. `stats`, when given,
    receives the numbers of candidates and of fitted patches.
    A tile of a larger cloud passes the whole cloud's `length` (l_d, default the bounding-box diagonal),
    its points' `ids` in the whole cloud and the whole cloud's `candidacy`; its points then get the normals
    they get in the whole cloud, wherever their neighbourhoods lie inside the tile. `neighbours` are kNN lists of
    the points (`neighbors.neighbour_lists`) at least as wide as MFPS's widest, when the caller shares them.
    """
    k0, k_max, k_bw = config.k0, config.scales[-1], config.k_bw
    points = check_array("points", np.ascontiguousarray(points, dtype=np.float64), "points",
                         min_points=max(k_max, k_bw))
    workers = workers or (len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)
    stats = {} if stats is None else stats

    def step(name: str, total: int = 1) -> AbstractContextManager[tqdm]:
        return _step(name, total, progress)

    width = max(k_max, k_bw)
    if neighbours is None:
        with step("kNN", len(points)):
            neighbours = neighbour_lists(points, width)
    neighbours = first_neighbours(neighbours, width)
    with step("A.1 candidates"):
        centroids, covs = covariances(points, neighbours[:, :k0])
        eigenvalues, normals = smallest_eigenvectors(covs)
        raw = raw_variation(eigenvalues)
        candidacy = cloud_candidacy(raw, config) if candidacy is None else candidacy
        candidates = np.flatnonzero(candidacy.candidates(raw))
        candidate = np.zeros(len(points), dtype=bool)
        candidate[candidates] = True
    stats["candidates"] = len(candidates)
    if len(candidates) == 0:
        return dict.fromkeys(METHODS, normals)
    with step("A.2 bandwidth"):
        sigma = residual_bandwidth(points, neighbours[:, :k0], centroids, normals, neighbours[:, :k_bw])
        sigma = np.maximum(sigma, SIGMA_FLOOR * (bbox_diagonal(points) if length is None else length))
    fits = []
    for k in config.scales:
        centres = np.flatnonzero(_touches(candidate, neighbours[:, :k]))
        stats[f"patches k={k}"] = len(centres)
        with step(f"A.3 patches k={k}", len(centres)) as bar:
            fits.append(fit_patches(points, neighbours[:, :k], centres, sigma, candidate, config.trials,
                                    config.seed, workers, bar.update, ids))
    with step("A.5 selection"):
        eta = eta_weights(config.scales, config.eta, config.beta)
        offsets = np.cumsum([0] + [len(f.m) for f in fits[:-1]], dtype=np.int32)
        selected = select_fitting_patches(
            points, centroids, candidates,
            np.concatenate([f.pair_candidate for f in fits]),
            np.concatenate([f.pair_patch + o for f, o in zip(fits, offsets, strict=True)]),
            np.concatenate([f.pair_consistency * eta_k for f, eta_k in zip(fits, eta, strict=True)]),
            np.concatenate([f.m for f in fits]), np.concatenate([f.n for f in fits]),
            config.theta_t, config.a_max)
    simple = normals.copy()
    normals[candidates], simple[candidates] = selected
    return dict(zip(METHODS, (normals, simple), strict=True))


@contextmanager
def _step(name: str, total: int, progress: bool) -> Iterator[tqdm]:
    """One step: a `profiling.stage`, with a progress bar (silent when progress is off)."""
    with stage(name), tqdm(total=total, desc=f"MFPS {name}", disable=not progress) as bar:
        yield bar
        bar.update(total - bar.n)


def _touches(candidate: np.ndarray, neighbours: np.ndarray) -> np.ndarray:
    """Whether each patch kNN_k(i) contains at least one candidate (only those patches are fitted)."""
    out = np.empty(len(neighbours), dtype=bool)
    for sl in chunks(len(neighbours), neighbours.shape[1]):
        out[sl] = candidate[neighbours[sl]].any(axis=1)
    return out

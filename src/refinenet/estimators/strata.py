"""Density matching (beyond the paper): a cloud denser than its noise allows is estimated as interleaved subsets.

The networks learned from clouds of a given density and noise. Their neighbourhoods are the k nearest points, which
shrink as the density grows while the noise does not: on a 100k-point mesh sample with 0.5% noise a 100-point patch
is, relative to its size, as noisy as one of a 10k-point sample with 1.6% noise, and the shipped networks' error is
56% above MFPS's there (studies/results/density_transfer.md). `strata_needed` measures the noise of a cloud
relative to its point spacing and halves the density until it is within a limit; `strata` splits the cloud into
that many interleaved random subsets (strata), each estimated on its own. Every point keeps its coordinates and
gets its normal from a subset whose noise the networks know; the subsets' spacing is sqrt(s) times the cloud's.
Each stratum sees only 1/s of the points, so `consensus` then gives every point the mean normal of its nearest
points of all strata, s nearly independent estimates of the same tangent plane.
"""

from __future__ import annotations

import numpy as np

from refinenet.estimators.baselines import jet_fit
from refinenet.geometry.neighbors import build_tree, chunks, knn, knn_blocks
from refinenet.geometry.scale import sample_rows, spacing_unit

#: Neighbours of the degree-2 jets whose residual measures the noise. Measured on the moai dev mesh: with 0.5% noise
#: at 100k points (1.33% of l_d) k = 16 reads 0.75, 32 reads 0.94 (a neighbourhood barely wider than the noise is a
#: blob); noise-free at 10k points, k = 32 reads 0.08 and 64 reads 0.17 (the surface's curvature).
NOISE_K = 32
#: Nearest points per stratum in a consensus, and at most this many in all (studies/results/strata.md).
CONSENSUS_PER_STRATUM = 4
CONSENSUS_MAX_K = 32
#: Neighbours whose normal is further than this from a point's own are taken to lie across a sharp feature and are
#: left out of its consensus (studies/results/strata.md: at the strata `auto_strata` picks, gates of 25-60 deg
#: differ by at most 0.12 deg of mean error; on 2 strata of moai at 0.5% by 1.8, where wider gates do better; an
#: ungated mean blurs sharp edges, tests/test_strata.py).
CONSENSUS_ANGLE = 40.0


def relative_noise(points: np.ndarray, spacing_ratio: float, seed: int = 0) -> float:
    """The noise of a cloud in percent of its spacing-derived l_d (`geometry.scale.spacing_unit`): the median RMS
    residual of degree-2 jets fitted to the NOISE_K nearest neighbours of sampled points.

    On a cloud like the training clouds this is their noise in percent of the diagonal, the unit of params.noise.
    """
    points = np.asarray(points, dtype=np.float64)
    tree = build_tree(points)
    idx = knn(points, NOISE_K, tree=tree, query=points[sample_rows(len(points), seed)], with_distances=False)[1]
    return 100.0 * float(np.median(jet_fit(points, idx)[1])) / spacing_unit(points, spacing_ratio, tree)


def strata(n_points: int, n_strata: int, seed: int = 0) -> list[np.ndarray]:
    """`n_strata` interleaved random subsets of the rows, as equal in size as can be."""
    return np.array_split(np.random.default_rng(seed).permutation(n_points), n_strata)


def strata_needed(points: np.ndarray, spacing_ratio: float, limit: float, min_points: int) -> int:
    """The smallest power of two whose strata have a relative noise of at most `limit` percent, or the largest
    whose strata keep `min_points` points."""
    n_strata = 1
    while (len(points) // (2 * n_strata) >= min_points
           and relative_noise(points[strata(len(points), n_strata)[0]], spacing_ratio) > limit):
        n_strata *= 2
    return n_strata


def consensus_k(n_strata: int) -> int:
    """The neighbours of a consensus over `n_strata` strata: about 4 of every stratum, at most 32."""
    return min(CONSENSUS_PER_STRATUM * n_strata, CONSENSUS_MAX_K)


def consensus(points: np.ndarray, normals: np.ndarray, k: int, angle: float = CONSENSUS_ANGLE) -> np.ndarray:
    """Unit normals (N, 3): each the sign-aligned mean of the `normals` of its k nearest points of the whole cloud
    (itself included) that lie within `angle` degrees of its own (`consensus_k` strata's worth of them)."""
    gate = np.cos(np.radians(angle))
    agreed = np.empty_like(normals)
    for block, idx in knn_blocks(points, min(k, len(points))):
        for sl in chunks(len(block), idx.shape[1]):
            rows = block[sl]
            around = normals[idx[sl]]
            dots = np.einsum("nkd,nd->nk", around, normals[rows])
            weights = np.where(np.abs(dots) >= gate, np.sign(dots), 0.0)  # the point itself always counts
            agreed[rows] = np.einsum("nk,nkd->nd", weights, around)
    return agreed / np.linalg.norm(agreed, axis=1, keepdims=True)

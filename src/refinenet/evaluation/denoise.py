"""The paper's denoising application (docs/algorithm.md §11): move points along estimated normals, then measure
the result against the true surface and reconstruct a surface for the figure.

Why: [P] shows estimated normals at work by denoising a noisy scan with them; the update only moves points along
the normals, so better normals give a cleaner cloud, and the reconstruction makes the difference visible. [P] gives
the update but not σ, the ball radius nor the reconstruction method, and [C] has no code for it; our choices are
the values of params.yaml `denoise` (`config.DenoiseConfig`).

The update, iterated a fixed number of times with the ball neighbourhoods N_i of the *input* cloud kept throughout:

    p_i ← p_i + γ_i Σ_{j∈N_i} [ w(n_i,n_j) ((p_j−p_i)·n_i) n_i + λ ((p_j−p_i)·n_j) n_j ],
    w(n_i,n_j) = exp(−‖n_i − n_j‖² / σ²),   γ_i = 1/(3|N_i|).

Its sums are sparse matrix products over the neighbour graph (W with entries w_ij, A its pattern), so an iteration
is two products with N×3 matrices and no per-pair arrays:

    Σ_j w_ij ((p_j−p_i)·n_i) n_i = n_i n_iᵀ (W p − (Σ_j w_ij) p_i)
    Σ_j ((p_j−p_i)·n_j) n_j     = A (n (n·p)) − (Σ_j n_j n_jᵀ) p_i
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from refinenet.atomic import atomic_path
from refinenet.errors import InputError
from refinenet.threads import native_threads

#: Poisson vertices whose density (Open3D's estimated octree depth of the vertex) lies more than this many octree
#: levels below the median are trimmed. Measured (depth 8, 20k points): a closed sphere loses none; a hemisphere
#: loses all vertices more than 0.04 from the data (the balloon closing it) and none of the supported ones, where the
#: 2nd percentile kept 955 of 1636 unsupported vertices and a margin of 0.5 cut 446 supported ones at the rim.
DENSITY_MARGIN = 1.0


def point_update(points: np.ndarray, normals: np.ndarray, radius: float, sigma: float, lam: float,
                 iterations: int) -> np.ndarray:
    """The denoised (N, 3) float64 points after `iterations` Jacobi steps of the update (every point moves from the
    previous step's positions); the inputs are not modified.

    N_i is the closed ball of `radius` around p_i in the input cloud, without p_i itself (its term is zero), and
    stays fixed; a point with no neighbours stays put. Normals are fixed, scaled to unit length, and each n_j is
    sign-aligned to n_i in w (the projections do not depend on the signs), so unoriented normals work.

    On curved surfaces the update shrinks the cloud: one step moves a clean unit sphere inwards by about
    (1 − λ) r²/12 − r⁴/(18σ²) (tests/test_denoise.py): 0.0038 after 20 steps at r = 0.02 l_d, 4x less at 0.01 l_d.

    measured: 100k random points on a noisy unit sphere, 30 neighbours each, 20 iterations: 1.0 s (0.45 s of it
    the neighbour search and graph, 0.55 s the iterations; best of 3 calls, single-threaded, scipy 1.17).
    """
    points = _cloud(points, "points")
    normals = _normals(normals, points)
    if not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"radius: must be a positive finite number, got {radius}")
    if not (np.isfinite(sigma) and sigma > 0):
        raise ValueError(f"sigma: must be a positive finite number, got {sigma}")
    if not np.isfinite(lam):
        raise ValueError(f"lam: must be finite, got {lam}")
    if isinstance(iterations, bool) or not isinstance(iterations, int | np.integer) or iterations < 0:
        raise ValueError(f"iterations: must be a non-negative integer, got {iterations!r}")

    n = len(points)
    pairs = cKDTree(points).query_pairs(radius, output_type="ndarray")
    rows, cols = np.concatenate([pairs[:, 0], pairs[:, 1]]), np.concatenate([pairs[:, 1], pairs[:, 0]])
    adjacency = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    rows = np.repeat(np.arange(n), np.diff(adjacency.indptr))  # the pairs again, in the matrix's order
    cos = np.abs(np.einsum("ij,ij->i", normals[rows], normals[adjacency.indices]))
    weights = sp.csr_matrix((np.exp(-(2.0 - 2.0 * cos).clip(min=0.0) / sigma**2), adjacency.indices,
                             adjacency.indptr), shape=(n, n))
    weight_sums = np.asarray(weights.sum(axis=1)).ravel()
    normal_sums = (adjacency @ (normals[:, :, None] * normals[:, None, :]).reshape(n, 9)).reshape(n, 3, 3)
    counts = np.diff(adjacency.indptr)
    gamma = np.divide(1.0, 3.0 * counts, out=np.zeros(n), where=counts > 0)

    # The expanded products subtract terms as large as the coordinates, so they run on positions relative to the
    # centroid; the result is the input plus the displacement, so a coordinate that never moves is returned as is.
    start = points - points.mean(axis=0)
    p = start.copy()
    for _ in range(iterations):
        along_own = np.einsum("ij,ij->i", normals, weights @ p - weight_sums[:, None] * p)
        along_theirs = adjacency @ (normals * np.einsum("ij,ij->i", normals, p)[:, None])
        along_theirs -= np.einsum("ijk,ik->ij", normal_sums, p)
        p += gamma[:, None] * (along_own[:, None] * normals + lam * along_theirs)
    return points + (p - start)


def surface_distance(points: np.ndarray, surface_points: np.ndarray, surface_normals: np.ndarray) -> np.ndarray:
    """(N,) distance of each point to a densely sampled surface: |(p − q)·n_q| for the nearest sample q.

    Why the tangent plane of q rather than ‖p − q‖: a point on the surface between samples is up to half the sample
    spacing h from the nearest one, which would read as residual noise; the plane distance is exact on flat parts
    and off by O(κh²) on curved ones (about 2e-5 on a unit sphere sampled with 100k points).
    """
    points = _cloud(points, "points")
    surface_points = _cloud(surface_points, "surface_points")
    surface_normals = _normals(surface_normals, surface_points, "surface_normals")
    nearest = cKDTree(surface_points).query(points, workers=native_threads())[1]
    return np.abs(np.einsum("ij,ij->i", points - surface_points[nearest], surface_normals[nearest]))


def poisson_surface(points: np.ndarray, normals: np.ndarray, depth: int = 8,
                    density_margin: float = DENSITY_MARGIN) -> tuple[np.ndarray, np.ndarray]:
    """Screened Poisson reconstruction (Open3D) of oriented points: (V, 3) float64 vertices and (F, 3) int64
    triangles, with the vertices more than `density_margin` octree levels below the median density removed.

    The normals are passed as given, so they must point consistently outward. Open3D runs single-threaded here:
    with its threads, two runs on the same input gave different meshes; with one they are identical (and not
    slower: about 3 s for 20k points at depth 8 on 2 cores).
    """
    import open3d as o3d

    points = _cloud(points, "points")
    given = np.asarray(normals, dtype=np.float64)
    _normals(given, points)
    if isinstance(depth, bool) or not isinstance(depth, int | np.integer) or not 1 <= depth <= 16:
        raise ValueError(f"depth: must be an integer in 1..16, got {depth!r}")
    if not (np.isfinite(density_margin) and density_margin >= 0):
        raise ValueError(f"density_margin: must be a non-negative finite number, got {density_margin}")
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    cloud.normals = o3d.utility.Vector3dVector(given)
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        mesh, densities = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(cloud, depth=int(depth),
                                                                                    n_threads=1)
    densities = np.asarray(densities)
    if len(densities):
        mesh.remove_vertices_by_mask(densities < np.median(densities) - density_margin)
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.triangles, dtype=np.int64)


def _cloud(points: np.ndarray, name: str) -> np.ndarray:
    """`points` as a finite (N, 3) float64 array of at least 3 rows."""
    array = np.asarray(points, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"{name}: expected shape (N, 3), got {array.shape}")
    if len(array) < 3:
        raise ValueError(f"{name}: at least 3 points needed, got {len(array)}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name}: contains NaN or inf")
    return array


def _normals(normals: np.ndarray, points: np.ndarray, name: str = "normals") -> np.ndarray:
    """`normals`, one finite non-zero vector per point, scaled to unit length."""
    array = np.asarray(normals, dtype=np.float64)
    if array.shape != points.shape:
        raise ValueError(f"{name}: shape {array.shape} does not match the points' {points.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name}: contains NaN or inf")
    lengths = np.linalg.norm(array, axis=1)
    if not (lengths > 0).all():
        raise ValueError(f"{name}: zero-length normal at row {int(np.argmin(lengths))}")
    return array / lengths[:, None]


#: Points of the dense clean-surface sample per point of the cloud, for `surface_distance` (a 100k-point cloud is
#: measured against 1M surface points).
SURFACE_SAMPLES = 10


def write_record(path: str | Path, points: Mapping[str, np.ndarray], normals: Mapping[str, np.ndarray],
                 distances: Mapping[str, np.ndarray]) -> None:
    """One cloud's denoising results (atomically): the denoised points per method with the normals that moved
    them, and the distance to the true surface, in l_d, per row (the noisy input and each method)."""
    with atomic_path(path) as tmp:
        np.savez(tmp, **{f"points/{m}": p.astype(np.float32) for m, p in points.items()},
                 **{f"normals/{m}": n.astype(np.float32) for m, n in normals.items()},
                 **{f"distance/{r}": d.astype(np.float32) for r, d in distances.items()})


def read_record(path: str | Path) -> dict[str, dict[str, np.ndarray]]:
    """`write_record`'s arrays by kind (points, normals, distance), then by method or row."""
    try:
        with np.load(path) as record:
            arrays = {name: record[name] for name in record.files}
    except (OSError, ValueError) as err:
        raise InputError(path, f"not a denoising record ({err})") from None
    return {kind: {n.split("/", 1)[1]: a for n, a in arrays.items() if n.startswith(f"{kind}/")}
            for kind in ("points", "normals", "distance")}

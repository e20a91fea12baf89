"""Height maps (HMPs, docs/algorithm.md §7, stage F): one m x m grid of local surface heights per normal of `nf`.

For point p_i and normal n_f the grid lies in the tangent plane T(p_i, n_f), with cell size h = rho_i / (m // 2)
and bin centres b_rc = p_i + (r - m//2) h u + (c - m//2) h v, u = normalize(n_f x e2), v = normalize(n_f x e1).
Each bin averages the signed heights (p - b_rc) . n_f of the cloud points within 0.9 h of b_rc, with weights
exp(-|p - b_rc|^2 / (2 h^2)), divided by rho_i; an empty bin is 0. (The release's "centre bin with exactly one
point is 0" rule needs no code: that point is p_i itself, at height 0.)

Axis convention: rows run along u, columns along v. When n_f = e3 of a det +1 frame, u = -e1 and v = e2: the
row index grows along -x' and the column index along +y' of the local frame; with det -1 both flip (the map
turns by 180 degrees).

Vectorisation. u and v are orthogonal to n_f but not, in general, to each other (a normal tilted diagonally
from e3 skews the grid), so bins are located in lattice coordinates (alpha, beta), the coefficients of a
candidate's in-plane offset on (h u, h v). While sin(u, v) > 0.9, a ball of radius 0.9 h around a bin only
reaches candidates in the 4 lattice cells around it, so each candidate is tested against the 4 corners of its
own cell instead of all m^2 bins; the rare strongly skewed grids (normals far from e3) test every bin. The test
itself uses |d - h (r u + c v)|^2 = |d|^2 - 2 h (r d.u + c d.v) + h^2 (r^2 + c^2 + 2 r c u.v), which needs no
inverse of the (u, v) metric and so holds for any skew. Candidates (all points within reach of the farthest
bin) are gathered once per point for all X normals, in spatially compact chunks.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from refinenet.geometry.neighbors import build_tree, chunks, knn

#: Bin ball radius in cells.
BIN_RADIUS = 0.9
#: cos^2(u, v) up to which only the 4 lattice-cell corners are tested: exact while sin(u, v) > BIN_RADIUS,
#: i.e. cos^2 < 1 - BIN_RADIUS^2, less a margin for rounding.
CORNER_SKEW = 1.0 - BIN_RADIUS ** 2 - 0.01
#: |n_f x e| below which that cross product is treated as zero and the in-plane fallback axis is used.
DEGENERATE = 1e-12


def height_maps(points: np.ndarray, nf: np.ndarray, frames: np.ndarray, m: int = 7, k: int = 100,
                extent: float | np.ndarray | None = None, tree: cKDTree | None = None,
                index: np.ndarray | None = None) -> np.ndarray:
    """Height maps (M x X x m x m, float32) of points[index] (all when None), one per normal of `nf` (N x 3X).

    rho_i (the half-extent) is the distance to the k-th nearest neighbour (self included), or `extent`: an
    absolute length, scalar or one per indexed point (e.g. the paper profile's ball radius, or rho computed
    once for the patches). `frames` (N x 3 x 3) are the §4 frames of the whole cloud. Normals are renormalised.
    """
    points = np.asarray(points, dtype=np.float64)
    index = np.arange(len(points)) if index is None else np.asarray(index)
    tree = tree if tree is not None else build_tree(points)
    centres = points[index]
    if extent is None:
        rho = knn(points, k, tree=tree, query=centres)[0][:, -1]
    else:
        rho = np.broadcast_to(np.asarray(extent, dtype=np.float64), (len(index),))
    half = m // 2
    cell = rho / half
    normals = np.asarray(nf)[index].astype(np.float64).reshape(len(index), -1, 3)
    normals /= np.linalg.norm(normals, axis=2, keepdims=True)
    n_maps = normals.shape[1]
    basis, cos = _grid_basis(normals, np.asarray(frames)[index].astype(np.float64), cell)
    skewed = cos ** 2 > CORNER_SKEW
    reach = rho * np.sqrt(2.0 + 2.0 * np.abs(cos).max(axis=1)) + BIN_RADIUS * cell  # farthest bin + its ball

    sizes = tree.query_ball_point(centres, reach, return_length=True, workers=-1)
    axes = [np.ascontiguousarray(points[:, a]) for a in range(3)]
    rank = np.empty(len(points), dtype=np.int64)
    rank[tree.indices] = np.arange(len(points))
    order = np.argsort(rank[index])  # leaf order: compact chunks keep the dual-tree query cheap
    heights = np.empty((len(index), n_maps, m, m), dtype=np.float32)
    for sl in chunks(len(index), int(sizes.max()) * 5 * n_maps):
        rows = order[sl]
        offsets, valid = _candidates(axes, centres[rows], reach[rows], tree)
        coords = offsets @ basis[rows]  # (n, K, 5X): a, b, alpha, beta, zeta of every normal
        _, _, alpha, beta, zeta = np.moveaxis(coords.reshape(*valid.shape, 5, n_maps), 2, 0)  # (n, K, X) views
        q = np.einsum("nkd,nkd->nk", offsets, offsets) / cell[rows, None] ** 2
        near = valid[:, :, None] & (zeta ** 2 <= BIN_RADIUS ** 2)
        skewed_here = skewed[rows, None]
        # Regular grids: the 4 corners of the lattice cell, for candidates whose cell touches the grid.
        regular = near & ~skewed_here & (np.abs(alpha) < half + 1) & (np.abs(beta) < half + 1)
        votes = [_votes(np.flatnonzero(regular), coords, q, cos[rows], m, every_bin=False)]
        if skewed_here.any():
            votes.append(_votes(np.flatnonzero(near & skewed_here), coords, q, cos[rows], m, every_bin=True))
        bins, w, z = (np.concatenate(parts) for parts in zip(*votes, strict=True))
        size = len(rows) * n_maps * m * m
        sum_w = np.bincount(bins, w, minlength=size)
        sum_wz = np.bincount(bins, w * z, minlength=size)
        mean = np.divide(sum_wz, sum_w, out=np.zeros(size), where=sum_w > 0)
        heights[rows] = (mean / half).reshape(len(rows), n_maps, m, m)
    return heights


def bin_axes(normals: np.ndarray, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Grid axes u = normalize(n_f x e2), v = normalize(n_f x e1) (each N x X x 3) for normals (N x X x 3).

    When n_f is parallel to e2 (resp. e1) that cross product vanishes; the fallback is the in-plane axis that
    keeps (v, u, n_f) right-handed as in the regular case: u = n_f x v (resp. v = u x n_f).
    """
    e1, e2 = frames[:, None, :, 0], frames[:, None, :, 1]
    u, v = np.cross(normals, e2), np.cross(normals, e1)
    u_len = np.linalg.norm(u, axis=2, keepdims=True)
    v_len = np.linalg.norm(v, axis=2, keepdims=True)
    u = u / np.maximum(u_len, DEGENERATE)
    v = v / np.maximum(v_len, DEGENERATE)
    u = np.where(u_len < DEGENERATE, np.cross(normals, v), u)
    v = np.where(v_len < DEGENERATE, np.cross(u, normals), v)
    return u, v


def _grid_basis(normals: np.ndarray, frames: np.ndarray, cell: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per grid (point, normal): the basis (n x 3 x 5X) that maps an offset d to (a, b, alpha, beta, zeta) in
    cells, i.e. its projections on u, v, the dual basis of (u, v) and n_f, and cos (n x X) = u . v.

    The dual basis (lattice coordinates) is only needed, and only well defined, on the regular grids.
    """
    u, v = bin_axes(normals, frames)
    cos = np.einsum("nxi,nxi->nx", u, v)
    inverse = np.divide(1.0, 1.0 - cos ** 2, out=np.zeros_like(cos), where=cos ** 2 <= CORNER_SKEW)[..., None]
    dual_u, dual_v = (u - cos[..., None] * v) * inverse, (v - cos[..., None] * u) * inverse
    basis = np.stack([u, v, dual_u, dual_v, normals], axis=1).transpose(0, 3, 1, 2) / cell[:, None, None, None]
    return basis.reshape(len(normals), 3, -1), cos


def _candidates(axes: list[np.ndarray], centres: np.ndarray, reach: np.ndarray,
                tree: cKDTree) -> tuple[np.ndarray, np.ndarray]:
    """Offsets p - p_i (n x K x 3) of the points within reach_i of each centre, zero-padded, and their mask.

    `axes` are the cloud's x, y and z coordinates as contiguous arrays (three 1-D gathers are faster than one).
    """
    pairs = build_tree(centres).sparse_distance_matrix(tree, reach.max(), output_type="ndarray")
    i, j = pairs["i"], pairs["j"]
    keep = np.flatnonzero(pairs["v"] <= reach[i])
    keep = keep[np.lexsort((j[keep], i[keep]))]  # by centre, then neighbour index: sums in a fixed order
    i, j = i[keep], j[keep]
    count = np.bincount(i, minlength=len(centres))
    width = int(count.max())
    slot = i * width + np.arange(len(i)) - (np.cumsum(count) - count)[i]
    offsets = np.zeros((len(centres) * width, 3))
    for a in range(3):
        offsets[slot, a] = axes[a][j] - centres[i, a]
    valid = np.zeros(len(centres) * width, dtype=bool)
    valid[slot] = True
    return offsets.reshape(len(centres), width, 3), valid.reshape(len(centres), width)


def _votes(ids: np.ndarray, coords: np.ndarray, q: np.ndarray, cos: np.ndarray, m: int,
           every_bin: bool) -> tuple[np.ndarray, ...]:
    """Flat bin ids, weights and heights (in cells) of the candidates `ids` (flat ids into n x K x X) that lie in
    a bin ball: tested against the 4 corners of their lattice cell, or against `every_bin` of skewed grids.

    `coords` (n x K x 5X) holds each candidate's projections a, b, zeta on u, v, n_f and its lattice coordinates
    alpha, beta; q (n x K) its squared distance to p_i; cos (n x X) is u . v per grid; all in cells. Distances
    use |d - r u - c v|^2 = q - 2 r a - 2 c b + r^2 + c^2 + 2 r c cos, so the skew needs no inverse.
    """
    half, n_maps = m // 2, cos.shape[1]
    candidate, normal = np.divmod(ids, n_maps)
    grid = candidate // q.shape[1] * n_maps + normal
    at = candidate * (5 * n_maps) + normal
    a, b, alpha, beta, zeta = (coords.ravel()[at + c * n_maps] for c in range(5))
    q, cos2 = q.ravel()[candidate], 2.0 * cos.ravel()[grid]
    if every_bin:
        span, r0 = m, np.full(len(ids), -float(half))
        c0 = r0
    else:
        span, r0, c0 = 2, np.floor(alpha), np.floor(beta)
    base = (grid * m + (r0 + half).astype(np.int64)) * m + (c0 + half).astype(np.int64)
    rows = [r0 + dr for dr in range(span)]
    cols = [c0 + dc for dc in range(span)]
    row_d2 = [q - 2.0 * r * a + r * r for r in rows]
    row_cross = [cos2 * r for r in rows]
    col_d2 = [c * c - 2.0 * c * b for c in cols]
    row_in = [np.abs(r) <= half for r in rows]
    col_in = [np.abs(c) <= half for c in cols]
    bins, weights, heights = [], [], []
    for dr in range(span):
        for dc in range(span):
            d2 = row_d2[dr] + col_d2[dc] + row_cross[dr] * cols[dc]
            hit = row_in[dr] & col_in[dc] & (d2 <= BIN_RADIUS ** 2)
            bins.append(base[hit] + (dr * m + dc))
            weights.append(np.exp(-0.5 * d2[hit].astype(np.float32)))
            heights.append(zeta[hit])
    return np.concatenate(bins), np.concatenate(weights), np.concatenate(heights)

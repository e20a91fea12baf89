"""Height maps (HMPs, docs/algorithm.md §7, stage F): one m x m grid of local surface heights per normal of `nf`.

For point p_i and normal n_f the grid lies in the tangent plane T(p_i, n_f), with cell size h = rho_i / (m // 2)
and bin centres b_rc = p_i + (r - m//2) h u + (c - m//2) h v, u = normalize(n_f x e2), v = normalize(n_f x e1).
Each bin averages the signed heights (p - b_rc) . n_f of the cloud points within 0.9 h of b_rc, with weights
exp(-|p - b_rc|^2 / (2 h^2)), divided by rho_i; an empty bin is 0. (The release's "centre bin with exactly one
point is 0" rule needs no code: that point is p_i itself, at height 0.)

Axis convention: rows run along u, columns along v. When n_f = e3 of a det +1 frame, u = -e1 and v = e2: the
row index grows along -x' and the column index along +y' of the local frame; with det -1 both flip (the map
turns by 180 degrees).

Search. u and v are orthogonal to n_f but not, in general, to each other (a normal tilted diagonally from e3
skews the grid), so bins are located in lattice coordinates (alpha, beta), the coefficients of a candidate's
in-plane offset on (h u, h v). While sin(u, v) > 0.9, a ball of radius 0.9 h around a bin only reaches
candidates in the 4 lattice cells around it, so each candidate is tested against the 4 corners of its own cell
instead of all m^2 bins; the rare strongly skewed grids (normals far from e3) test every bin. The test itself
uses |d - h (r u + c v)|^2 = |d|^2 - 2 h (r d.u + c d.v) + h^2 (r^2 + c^2 + 2 r c u.v), which needs no inverse
of the (u, v) metric and so holds for any skew. Candidates (all points within reach of the farthest bin) are
gathered once per point for all X normals from a hashed grid (`geometry.ball`), in a numba kernel that holds
one point's sums at a time: memory does not grow with the candidates, and the kernel releases the GIL, so
threads split the points.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from refinenet.geometry.ball import ball_grid
from refinenet.geometry.neighbors import nearest_at

#: Bin ball radius in cells.
BIN_RADIUS = 0.9
#: cos^2(u, v) up to which only the 4 lattice-cell corners are tested: exact while sin(u, v) > BIN_RADIUS,
#: i.e. cos^2 < 1 - BIN_RADIUS^2, less a margin for rounding.
CORNER_SKEW = 1.0 - BIN_RADIUS ** 2 - 0.01
#: |n_f x e| below which that cross product is treated as zero and the in-plane fallback axis is used.
DEGENERATE = 1e-12


def height_maps(points: np.ndarray, nf: np.ndarray, frames: np.ndarray, m: int = 7, k: int = 100,
                extent: float | np.ndarray | None = None, tree: cKDTree | None = None,
                index: np.ndarray | None = None, neighbours: np.ndarray | None = None) -> np.ndarray:
    """Height maps (M x X x m x m, float32) of points[index] (all when None), one per normal of `nf` (N x 3X).

    rho_i (the half-extent) is the distance to the k-th nearest neighbour (self included), or `extent`: an
    absolute length, scalar or one per indexed point (e.g. the paper profile's ball radius, or rho computed
    once for the patches). `neighbours` (M x k or wider), the indexed points' kNN lists when the caller shares
    them, give that k-th neighbour without a query. `frames` (N x 3 x 3) are the §4 frames of the whole cloud.
    Normals are renormalised.
    """
    points = np.asarray(points, dtype=np.float64)
    index = np.arange(len(points)) if index is None else np.asarray(index)
    if extent is None:
        rho = nearest_at(points, k, index, tree, neighbours)[0]
    else:
        rho = np.broadcast_to(np.asarray(extent, dtype=np.float64), (len(index),))
    half = m // 2
    cell = rho / half
    nf = np.asarray(nf)
    normals = nf[index].astype(np.float64).reshape(len(index), nf.shape[1] // 3, 3)
    normals /= np.linalg.norm(normals, axis=2, keepdims=True)
    axes, cos = _grid_axes(normals, np.asarray(frames)[index].astype(np.float64), cell)
    reach = rho * np.sqrt(2.0 + 2.0 * np.abs(cos).max(axis=1)) + BIN_RADIUS * cell  # farthest bin + its ball
    heights = np.empty((len(index), normals.shape[1], m, m), dtype=np.float32)
    if len(index):
        grid = ball_grid(points, float(np.median(reach)))
        _maps(grid.points, grid.keys, grid.dims, grid.origin, grid.cell, grid.rank[index], reach, 1.0 / cell ** 2,
              axes, cos, cos ** 2 > CORNER_SKEW, heights)
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


def _grid_axes(normals: np.ndarray, frames: np.ndarray, cell: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per point: the axes (n x 15 x X, i.e. 5 x 3 x X) that map an offset d to (a, b, alpha, beta, zeta) in cells
    on each of its X grids, i.e. its projections on u, v, the dual basis of (u, v) and n_f, and cos (n x X) =
    u . v. The grids are the last axis, so that the kernel projects a candidate on all X at once in vector
    instructions.

    The dual basis (lattice coordinates) is only needed, and only well defined, on the regular grids.
    """
    u, v = bin_axes(normals, frames)
    cos = np.einsum("nxi,nxi->nx", u, v)
    inverse = np.divide(1.0, 1.0 - cos ** 2, out=np.zeros_like(cos), where=cos ** 2 <= CORNER_SKEW)[..., None]
    dual_u, dual_v = (u - cos[..., None] * v) * inverse, (v - cos[..., None] * u) * inverse
    axes = np.stack([u, v, dual_u, dual_v, normals], axis=2) / cell[:, None, None, None]
    return np.ascontiguousarray(axes.transpose(0, 2, 3, 1)).reshape(len(axes), 15, axes.shape[1]), cos


@njit(nogil=True, cache=True)
def _maps(points, keys, dims, origin, grid_cell, centres, reach, inverse_cell2, axes, cos, skewed, out):
    """Fill out[row] with the maps of the grid-sorted point centres[row]: every point within reach[row] votes,
    with weight exp(-|d - b|^2 / 2) (in cells), for the bins whose ball (radius BIN_RADIUS) holds it."""
    n_maps, m = out.shape[1], out.shape[2]
    half = m // 2
    sum_w = np.empty((n_maps, m, m))
    sum_wz = np.empty((n_maps, m, m))
    low, high = np.empty(3, np.int64), np.empty(3, np.int64)
    projections = np.empty((5, n_maps))
    for row in range(len(centres)):
        sum_w[:] = 0.0
        sum_wz[:] = 0.0
        p, t = points[centres[row]], axes[row]
        r = reach[row]
        for a in range(3):
            low[a] = max(int((p[a] - r - origin[a]) / grid_cell), 0)
            high[a] = min(int((p[a] + r - origin[a]) / grid_cell), dims[a] - 1)
        for i in range(low[0], high[0] + 1):
            for j in range(low[1], high[1] + 1):
                first = (i * dims[1] + j) * dims[2]
                start = np.searchsorted(keys, first + low[2])
                stop = np.searchsorted(keys, first + high[2], side="right")
                for c in range(start, stop):
                    d0, d1, d2 = points[c, 0] - p[0], points[c, 1] - p[1], points[c, 2] - p[2]
                    dist2 = d0 * d0 + d1 * d1 + d2 * d2
                    if dist2 > r * r:
                        continue
                    for s in range(5):
                        for x in range(n_maps):
                            projections[s, x] = d0 * t[3 * s, x] + d1 * t[3 * s + 1, x] + d2 * t[3 * s + 2, x]
                    _vote(projections, dist2 * inverse_cell2[row], cos[row], skewed[row], half, sum_w, sum_wz)
        for x in range(n_maps):
            for b0 in range(m):
                for b1 in range(m):
                    w = sum_w[x, b0, b1]
                    out[row, x, b0, b1] = sum_wz[x, b0, b1] / w / half if w > 0 else 0.0


@njit(nogil=True, cache=True)
def _vote(projections, q, cos, skewed, half, sum_w, sum_wz):
    """Add one candidate (its (a, b, alpha, beta, zeta) on every grid, its squared length q, in cells) to the bins
    of every grid whose ball holds it: the 4 corners of its lattice cell on a regular grid, every bin on a skewed
    one. Distances use |d - r u - c v|^2 = q - 2 r a - 2 c b + r^2 + c^2 + 2 r c cos, in cells."""
    for x in range(len(cos)):
        zeta = projections[4, x]
        if zeta * zeta > BIN_RADIUS ** 2:
            continue
        a, b = projections[0, x], projections[1, x]
        if skewed[x]:
            r0, c0, span = -half, -half, 2 * half + 1
        else:
            alpha, beta = projections[2, x], projections[3, x]
            if abs(alpha) >= half + 1 or abs(beta) >= half + 1:
                continue
            r0, c0, span = int(np.floor(alpha)), int(np.floor(beta)), 2
        for dr in range(span):
            r = r0 + dr
            if abs(r) > half:
                continue
            for dc in range(span):
                c = c0 + dc
                if abs(c) > half:
                    continue
                dist2 = q - 2.0 * r * a + r * r + c * c - 2.0 * c * b + 2.0 * cos[x] * r * c
                if dist2 <= BIN_RADIUS ** 2:
                    w = np.exp(-0.5 * dist2)
                    sum_w[x, r + half, c + half] += w
                    sum_wz[x, r + half, c + half] += w * zeta

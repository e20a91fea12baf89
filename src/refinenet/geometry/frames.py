"""Per-point frames from the normal tensor (docs/algorithm.md §4, stage C).

R_i = [e1 e2 e3] (columns, ascending eigenvalues) of T_i = sum_x n_x n_x^T over the X normals of `nf`.
Rotating normals, patches and targets into this frame (v' = R^T v) removes the global orientation that the
network would otherwise have to learn.

Two sign conventions; in both, e3 is put on n_first's side (the whole matrix is negated when n_first . e3 <= 0):
* `canonical` (recommended): e2 is chosen so that sum_x n_x . e2 >= 0, then e1 = e2 x e3 (det +1).
  Invariances: T, and so e3, is unchanged by flipping any n_x with x >= 1; R is then unchanged while the flip
  preserves the sign of sum_x n_x . e2, and otherwise turns by 180 degrees about e3 (e1, e2 -> -e1, -e2).
  Flipping the whole field turns R by 180 degrees about e1 (outside the tie fallback), so the local normals
  are mirrored in x' ((x', y', z') -> (-x', y', z')): with e3 tied to n_first and det +1, one in-plane axis
  has to mirror.
* `faithful`: the raw LAPACK signs of numpy's SVD of the 3 x X normal matrix, reversed to ascending order, as
  the release computes them (e1, e2 signs arbitrary, det +-1).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

#: |sum_x n_x . e2| below this is rounding noise of an exact zero (e.g. all X normals equal, so e2 is orthogonal
#: to each of them); the canonical e2 sign then falls back to its largest-magnitude component.
TIE_TOLERANCE = 1e-9


def normal_frames(nf: np.ndarray, mode: Literal["canonical", "faithful"] = "canonical") -> np.ndarray:
    """Frames R (N x 3 x 3, float64), columns [e1 e2 e3], from `nf` (N x 3X); n_first = nf[:, :3]."""
    nf = np.asarray(nf)
    normals = nf.reshape(len(nf), -1, 3)
    if mode == "faithful":
        frames = np.linalg.svd(normals.transpose(0, 2, 1))[0][:, :, ::-1]  # descending -> ascending
    elif mode == "canonical":
        normals = normals.astype(np.float64)
        frames = np.linalg.eigh(np.einsum("nxi,nxj->nij", normals, normals))[1]
    else:
        raise ValueError(f"unknown frame mode {mode!r}; expected 'canonical' or 'faithful'")
    frames = frames.astype(np.float64)
    n_first = normals[:, 0].astype(np.float64)
    frames[np.einsum("ni,ni->n", n_first, frames[:, :, 2]) <= 0] *= -1.0
    if mode == "canonical":
        e2, e3 = frames[:, :, 1], frames[:, :, 2]
        side = np.einsum("nxi,ni->n", normals, e2)
        largest = np.take_along_axis(e2, np.abs(e2).argmax(axis=1)[:, None], axis=1)[:, 0]
        e2 = e2 * np.where(np.abs(side) > TIE_TOLERANCE, np.sign(side), np.sign(largest))[:, None]
        frames = np.stack([np.cross(e2, e3), e2, e3], axis=2)
    return frames


def to_local(frames: np.ndarray, v: np.ndarray) -> np.ndarray:
    """v' = R^T v for vectors (N x 3) or stacks of vectors (N x K x 3: normals, patch points)."""
    return np.einsum("nji,n...j->n...i", frames, v)


def to_world(frames: np.ndarray, v: np.ndarray) -> np.ndarray:
    """v = R v', the inverse of `to_local`, e.g. for the network's local-frame prediction."""
    return np.einsum("nij,n...j->n...i", frames, v)


def target_sign(g: np.ndarray, n0: np.ndarray) -> np.ndarray:
    """g flipped where g . n0 < 0, row by row: the clean-room target rule (§4), orienting g by a reference n0."""
    return np.where((np.einsum("...i,...i->...", g, n0) < 0)[..., None], -g, g)

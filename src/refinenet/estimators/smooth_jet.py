"""Beyond the paper: a degree-2 jet's normal on the points whose neighbourhood a quadric explains
(`FeatureConfig.smooth_jet`).

MFPS keeps PCA with K = 50 wherever its surface-variation test finds no feature, and fits patches wherever it
finds one, also on curved smooth surfaces (an ellipsoid's tips), where those patches are wrong by 10 degrees and
more; Jet with K = 100 is better on both (studies/README.md). Which points a jet may take is
decided by its own fit: where the RMS residual of the K = 100 jet is within `ratio` times the cloud's noise, the
quadric explains the neighbourhood; across a crease or a groove it does not. The noise is the median residual of
K = 20 jets: neighbourhoods that small lie on one smooth piece at most points even of a feature-rich shape.
"""

from __future__ import annotations

import numpy as np

from refinenet.estimators.baselines import jet_fit
from refinenet.geometry.frames import target_sign
from refinenet.geometry.neighbors import build_tree, first_neighbours, knn

#: Neighbours of the jet whose normal replaces the initial one: the paper's Jet K.
JET_K = 100
#: Neighbours of the jets whose median residual measures the cloud's noise.
NOISE_K = 20


def point_noise(points: np.ndarray, index: np.ndarray | None = None) -> np.ndarray:
    """RMS residuals of the K = NOISE_K jets at `points[index]` (default: every point); their median over a whole
    cloud is the noise `smooth_jet_normals` compares with (a tiled cloud pools its tiles' own points)."""
    points = np.asarray(points, dtype=np.float64)
    query = None if index is None else points[index]
    return jet_fit(points, knn(points, NOISE_K, tree=build_tree(points), query=query, with_distances=False)[1])[1]


def jet_and_noise(points: np.ndarray, noise: float | None = None,
                  neighbours: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """The K = JET_K jets' normals (N, 3) and RMS residuals (N,) at every point, and `noise` (default: the median
    of `point_noise` over these points). `neighbours`: the points' kNN lists, if shared, at least JET_K wide."""
    points = np.asarray(points, dtype=np.float64)
    k = min(JET_K, len(points))
    neighbours = knn(points, k, tree=build_tree(points), with_distances=False)[1] if neighbours is None \
        else first_neighbours(neighbours, k)
    if noise is None:
        noise = float(np.median(jet_fit(points, neighbours[:, :NOISE_K])[1]))
    normals, residuals = jet_fit(points, neighbours)
    return normals, residuals, noise


def smooth_jet_normals(points: np.ndarray, initial: np.ndarray, ratio: float,
                       noise: float | None = None, neighbours: np.ndarray | None = None) -> np.ndarray:
    """`initial` (N, 3) with the K = JET_K jet normal, on the initial normal's side, wherever that jet's RMS
    residual is below `ratio` x `noise` (`jet_and_noise`, which takes `neighbours`)."""
    normals, residuals, noise = jet_and_noise(points, noise, neighbours)
    smooth = residuals < ratio * noise
    out = np.array(initial, copy=True)
    out[smooth] = target_sign(normals[smooth], out[smooth]).astype(out.dtype)
    return out

"""The length unit l_d of a cloud: what the paper's radii (filter ball r_f, ball patches, height-map extent) are
fractions of.

The paper takes l_d to be the bounding-box diagonal, which fits its benchmark (whole objects of 100k points) and is
what the pipeline uses. On a user's cloud the diagonal says nothing about the neighbourhoods: a 100 m street tile
and a 10 cm scan of a statuette differ by 1000x in diagonal at the same point count. `spacing_unit` instead derives
l_d from the local point spacing, scaled so that on the training clouds it equals their diagonal: a radius of r_f
l_d then holds as many points on any cloud as it held in training, which is what the networks learned from.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from refinenet.data.noise import bbox_diagonal
from refinenet.geometry.neighbors import build_tree
from refinenet.threads import native_threads

#: The spacing of a cloud is the median distance from a point to its SPACING_K-th nearest neighbour (self
#: excluded): the nearest neighbour alone is dominated by noise, 16 neighbours sample the surface density.
SPACING_K = 16
#: Points whose neighbour distance is measured (a seeded uniform subset); the median of 20k distances is stable to
#: about 1% and costs the same for any cloud size.
SPACING_SAMPLES = 20_000


def neighbour_distance(points: np.ndarray, k: int, quantile: float = 0.5, tree: cKDTree | None = None,
                       seed: int = 0) -> float:
    """A quantile of the distance from a point to its k-th nearest neighbour (self excluded), over a seeded
    subset of SPACING_SAMPLES points."""
    points = np.asarray(points, dtype=np.float64)
    tree = tree if tree is not None else build_tree(points)
    sample = points[sample_rows(len(points), seed)]
    return float(np.quantile(tree.query(sample, min(k + 1, len(points)), workers=native_threads())[0][:, -1], quantile))


def sample_rows(n_points: int, seed: int = 0) -> np.ndarray | slice:
    """The rows of a cloud that a whole-cloud statistic is measured on: a seeded uniform subset of SPACING_SAMPLES,
    or every row of a smaller cloud."""
    if n_points <= SPACING_SAMPLES:
        return slice(None)
    return np.random.default_rng(seed).choice(n_points, SPACING_SAMPLES, replace=False)


def point_spacing(points: np.ndarray, tree: cKDTree | None = None) -> float:
    """The median distance to the SPACING_K-th nearest neighbour."""
    return neighbour_distance(points, SPACING_K, 0.5, tree)


def spacing_ratio(points: np.ndarray) -> float:
    """point_spacing / bbox_diagonal of one cloud: what a shipped network records of its training clouds."""
    return point_spacing(points) / bbox_diagonal(points)


def spacing_unit(points: np.ndarray, ratio: float, tree: cKDTree | None = None) -> float:
    """l_d from the point spacing: the diagonal a training cloud of the same spacing would have had."""
    return point_spacing(points, tree) / ratio

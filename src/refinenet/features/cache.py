"""The per-cloud feature cache (docs/algorithm.md §0, stages B, C and F): filtered normals, frames and height maps.

These depend only on the points and the initial normals (never on ground truth, so the same code serves test
clouds) and cost far more than a training step's share, so they are computed once per cloud and stored. The
point patches (stage E) are not cached: 100 points per point would dwarf the rest, and kNN queries per batch
are cheap.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from refinenet.config import FeatureConfig
from refinenet.data import io
from refinenet.data.noise import bbox_diagonal
from refinenet.errors import InputError
from refinenet.estimators.baselines import fit_normals
from refinenet.estimators.smooth_jet import JET_K, smooth_jet_normals
from refinenet.features.filtering import bilateral_filter
from refinenet.features.heightmaps import height_maps
from refinenet.geometry.frames import normal_frames, target_sign
from refinenet.geometry.neighbors import build_tree
from refinenet.profiling import stage
from refinenet.threads import thread_map

#: Points per height-map call: the unit of the progress bar (height_maps bounds its own memory per call).
HEIGHT_STEP = 10_000


@dataclass(frozen=True)
class Features:
    """One cloud's cached features, row i belonging to point i, or to point centres[i] where the rows cover only
    some points (a tile's own points; the scored points of a test cloud, `data.clouds.scored_points`)."""

    nf: np.ndarray
    """(N, 3X) float32, world frame: [n_first, f(s1, r1), ...] as `bilateral_filter` orders them, then the wide
    PCA and jet normals where `FeatureConfig.pca_k` and `jet_k` ask for them."""
    frames: np.ndarray
    """(N, 3, 3) float32: columns [e1 e2 e3] of the normal-tensor frame (§4)."""
    heights: np.ndarray
    """(N, X, m, m) float16 or float32: one height map per normal of nf, in nf's order."""
    centres: np.ndarray | None = None
    """(N,) the point of each row where the rows cover only some points; None: all, in order."""
    n_normals: int = field(init=False)

    def __post_init__(self) -> None:
        n, width = self.nf.shape
        object.__setattr__(self, "n_normals", width // 3)
        if width % 3 or self.frames.shape != (n, 3, 3) or self.heights.shape[:2] != (n, width // 3) \
                or (self.centres is not None and self.centres.shape != (n,)):
            raise ValueError(f"inconsistent feature shapes: nf {self.nf.shape}, frames {self.frames.shape}, "
                             f"heights {self.heights.shape}"
                             + ("" if self.centres is None else f", centres {self.centres.shape}"))

    def __len__(self) -> int:
        return len(self.nf)

    @property
    def n_first(self) -> np.ndarray:
        """(N, 3) the first normal of nf: the initial normal when X = 9; the sign reference of frames and targets."""
        return self.nf[:, :3]

    @property
    def points(self) -> np.ndarray:
        """(N,) the point of each row."""
        return np.arange(len(self)) if self.centres is None else self.centres

    def rows(self, index: np.ndarray) -> Features:
        """The features of some rows, which keep the points they belong to."""
        return Features(nf=self.nf[index], frames=self.frames[index], heights=self.heights[index],
                        centres=self.points[index])


def compute_features(points: np.ndarray, initial_normals: np.ndarray, config: FeatureConfig,
                     progress: bool = False, length: float | None = None,
                     centres: np.ndarray | None = None, workers: int = 1, noise: float | None = None,
                     neighbours: np.ndarray | None = None) -> Features:
    """Stages B, C and F for one cloud: filtered normals, frames, then height maps (the slow part).

    `length` is l_d, the unit of r_f and hmp_extent (default: the bounding-box diagonal; `geometry.scale`).
    `centres` limits the rows to those points (a tile's own points; its margin only lends neighbours).
    `workers` threads build the height maps (numpy releases the GIL); each map depends on its point alone, so
    the result does not depend on it. `noise` is the whole cloud's for a tile (`FeatureConfig.smooth_jet`).
    `neighbours` are the points' kNN lists, when the caller shares them (`neighbors.neighbour_lists`), at least
    `features_width(config)` wide.
    """
    points = np.asarray(points, dtype=np.float64)
    if config.smooth_jet is not None:
        with stage("smooth jet"):
            initial_normals = smooth_jet_normals(points, initial_normals, config.smooth_jet, noise, neighbours)
    length = bbox_diagonal(points) if length is None else length
    rows = np.arange(len(points)) if centres is None else np.asarray(centres)
    with stage("filtered normals"):
        nf = bilateral_filter(points, initial_normals, r_f=config.r_f, sigma_s=config.sigma_s,
                              sigma_r=config.sigma_r, include_initial=config.include_initial, length=length)
        nf = np.hstack([nf, *(wide_normals(points, nf[:, :3], method, k, neighbours)
                              for method, k in config.wide_normals)])
        frames = normal_frames(nf, config.frame_mode)
    with stage("height maps"):
        heights = _height_maps(points, nf, frames, config, length, rows, workers, progress,
                               None if neighbours is None else neighbours[rows])
    return Features(nf=nf[rows], frames=frames[rows].astype(np.float32), heights=heights,
                    centres=None if centres is None else rows)


def features_width(config: FeatureConfig) -> int:
    """The widest kNN list the features take (0: none): the smooth-point jet's, the wide jet's and rho's."""
    return max([JET_K if config.smooth_jet is not None else 0, config.hmp_k if config.hmp_extent is None else 0,
                *(k for method, k in config.wide_normals if method == "jet")])


def _height_maps(points: np.ndarray, nf: np.ndarray, frames: np.ndarray, config: FeatureConfig, length: float,
                 rows: np.ndarray, workers: int, progress: bool, neighbours: np.ndarray | None) -> np.ndarray:
    """Stage F for the points `rows` (whose kNN lists are `neighbours`, if shared), in steps of HEIGHT_STEP points
    over `workers` threads."""
    tree = build_tree(points) if neighbours is None and config.hmp_extent is None else None
    extent = None if config.hmp_extent is None else config.hmp_extent * length
    heights = np.empty((len(rows), config.n_normals, config.hmp_size, config.hmp_size), dtype=config.heights_dtype)

    steps = [slice(start, start + HEIGHT_STEP) for start in range(0, len(rows), HEIGHT_STEP)]
    with tqdm(total=len(steps), desc="height maps", disable=not progress) as bar:
        def fill(part: slice) -> None:
            heights[part] = height_maps(points, nf, frames, m=config.hmp_size, k=config.hmp_k, extent=extent,
                                        tree=tree, index=rows[part],
                                        neighbours=None if neighbours is None else neighbours[part])
            bar.update()

        thread_map(fill, steps, workers)
    return heights


def wide_normals(points: np.ndarray, n_first: np.ndarray, method: str, k: int,
                 neighbours: np.ndarray | None = None) -> np.ndarray:
    """(N, 3) float32 normals of a wide-neighbourhood fit (`FeatureConfig.wide_normals`: PCA, or a degree-2 jet, of
    k neighbours), each flipped to its n_first's side as the filtered normals are, so that the extra normal carries
    no sign of its own. `neighbours`: the points' kNN lists, if shared."""
    normals = fit_normals(points, method, min(k, len(points)), neighbours=neighbours)
    return target_sign(normals.astype(np.float32), n_first)


def save_features(path: str | Path, features: Features, meta: dict[str, Any]) -> None:
    """Write an uncompressed .npz atomically; `meta` (JSON-serialisable, e.g. the FeatureConfig) is stored with it."""
    arrays = {"nf": features.nf, "frames": features.frames, "heights": features.heights}
    io.save_record(path, arrays if features.centres is None else {**arrays, "centres": features.centres}, meta)


def load_features(path: str | Path) -> tuple[Features, dict[str, Any]]:
    """The features and meta written by `save_features`; InputError for a missing or malformed file."""
    arrays, meta = io.load_record(path, ("nf", "frames", "heights"), "feature cache")
    try:
        features = Features(nf=arrays["nf"], frames=arrays["frames"], heights=arrays["heights"],
                            centres=arrays.get("centres"))
    except ValueError as err:
        raise InputError(path, str(err)) from None
    return features, meta


def load_for_cloud(cloud_path: str | Path, features_path: str | Path) -> tuple[io.Cloud, Features]:
    """A cloud record and its feature cache, checked to describe the same points."""
    cloud = io.read_cloud(cloud_path)
    features, _ = load_features(features_path)
    if features.centres is None and len(features) != len(cloud):
        raise InputError(features_path, f"{len(features)} feature rows for {len(cloud)} points of {cloud_path}")
    if features.centres is not None and len(features) and not 0 <= features.centres.min() <= features.centres.max() \
            < len(cloud):
        raise InputError(features_path, f"feature rows of points beyond the {len(cloud)} of {cloud_path}")
    return cloud, features

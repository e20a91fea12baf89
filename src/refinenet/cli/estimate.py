"""Normals of a user's cloud, any size: the chain behind `refinenet normals`.

Initial normals (MFPS, or any estimator's through `initial`), the feature cache and the shipped networks, run on
interleaved subsets of a cloud that is denser than its noise allows (`estimators.strata`), and tile by tile
(`geometry.tiles`) so that memory is bounded by the tile, not the cloud. Every whole-cloud quantity is computed
once and handed to each tile: the length unit l_d (`geometry.scale`), MFPS's candidacy statistics, and each
point's id for MFPS's random trials. With a margin that covers the farthest neighbourhood chain, a tile then
gives its points the normals the whole cloud gives them.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from tqdm import tqdm

from refinenet.config import Params
from refinenet.data.noise import bbox_diagonal
from refinenet.estimators.baselines import baseline_normals, neighbourhood_size
from refinenet.estimators.mfps import Candidacy, cloud_candidacy, mfps_normals, point_variation
from refinenet.estimators.smooth_jet import point_noise
from refinenet.estimators.strata import consensus, consensus_k, strata, strata_needed
from refinenet.features.cache import compute_features, features_width
from refinenet.geometry.neighbors import build_tree, neighbour_lists
from refinenet.geometry.scale import neighbour_distance, spacing_unit
from refinenet.geometry.tiles import Tile, tiles
from refinenet.network.inference import refine_normals
from refinenet.network.release import Release
from refinenet.profiling import stage

METHODS = ("refinenet", "mfps", "pca", "jet")
SCALES = ("spacing", "diagonal")
#: Own points per tile. A tile of 500k points and its margin peak at about 2.5 GB (MFPS's neighbour lists and
#: the height maps dominate); smaller clouds are one tile.
TILE_POINTS = 500_000
#: MFPS reaches this many k_bw-neighbourhood radii from a point: patches that contain it (1), their members (2),
#: the members' bandwidth neighbourhoods (3) and the k0-patches that set their residuals (4, 5).
MFPS_REACH = 5
#: The feature cache and the point patches reach this many patch radii (height-map bins lie within 2 rho).
FEATURE_REACH = 3
#: Margins use this quantile of the neighbour distance, so that all but the sparsest points are covered.
REACH_QUANTILE = 0.99


def min_points(params: Params, method: str, refine_initial: bool) -> int:
    """The fewest points a cloud needs for `method`: its largest neighbourhood."""
    if method in ("pca", "jet"):
        return neighbourhood_size(params.baselines, method, None)
    network = max(params.features.hmp_k, params.patches.k)
    if method == "refinenet" and refine_initial:
        return network
    mfps = max(params.mfps.scales[-1], params.mfps.k_bw)
    return mfps if method == "mfps" else max(mfps, network)


def noise_limit(params: Params) -> float:
    """The relative noise (`estimators.strata.relative_noise`) a stratum may have: the largest test noise of the
    benchmark (BigNoise's 0.5% of the diagonal at the training density). The training's largest, 0.3%, splits
    clouds that are better whole (studies/results/strata.md)."""
    return max(max(levels) for levels in params.noise.test.values())


def auto_strata(points: np.ndarray, release: Release, method: str, refine_initial: bool) -> int:
    """How many interleaved subsets `method` estimates the cloud as: for Refine-Net as many as bring each subset's
    noise within `noise_limit`, the networks' training; 1 for the estimators alone, which are kept as published
    (MFPS on strata gains at heavy noise and loses at light noise: studies/results/strata.md).

    No stratum has fewer points than a training cloud: the rule is measured up to there, and beyond it a rough
    real surface keeps asking for more (on the street scan rue_madame_28 the relative noise falls by 7% per halving
    of the density, where noise falls by 20-30%: its roughness is mostly geometry).
    """
    if method != "refinenet":
        return 1
    params = release.params
    return strata_needed(points, release.spacing_ratio, noise_limit(params),
                         max(min_points(params, method, refine_initial), params.data.n_points))


def estimate_normals(points: np.ndarray, release: Release, method: str = "refinenet",
                     initial: np.ndarray | None = None, scale: str = "spacing", device: str = "auto",
                     tile_points: int = TILE_POINTS, workers: int = 1, progress: bool = False,
                     n_strata: int | None = None, reconcile: bool = True) -> np.ndarray:
    """Unit, unoriented normals (N, 3) of a cloud by `method`, with the release's settings (and networks).

    `initial` (N, 3) replaces MFPS as the normals Refine-Net refines. `scale` picks l_d: the point spacing
    calibrated on the training clouds, or the paper's bounding-box diagonal. `n_strata` interleaved subsets are
    estimated on their own (None: `auto_strata`'s choice), then reconciled by `estimators.strata.consensus` unless
    `reconcile` is False (studies/strata.py compares both).
    """
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r} (one of {', '.join(METHODS)})")
    if scale not in SCALES:
        raise ValueError(f"unknown scale {scale!r} (one of {', '.join(SCALES)})")
    points = np.ascontiguousarray(points, dtype=np.float64)
    if n_strata is None:
        n_strata = auto_strata(points, release, method, initial is not None)
    normals = np.empty_like(points)
    for rows in tqdm(stratum_rows(len(points), n_strata), desc="strata", unit="stratum",
                     disable=not progress or n_strata == 1):
        sub, given = stratum_cloud(points, initial, rows, n_strata)
        shared, layout = cloud_layout(sub, release, method, initial is not None, scale, tile_points,
                                      progress and n_strata == 1)
        inner = progress and n_strata == 1 and len(layout) == 1
        for tile in tqdm(layout, desc="tiles", unit="tile", disable=not progress or n_strata > 1 or len(layout) == 1):
            normals[rows[tile.own]] = tile_normals(sub, tile, shared, release, method, given, device, workers, inner)
    return reconciled(points, normals, n_strata) if reconcile else normals


def stratum_cloud(points: np.ndarray, initial: np.ndarray | None, rows: np.ndarray,
                  n_strata: int) -> tuple[np.ndarray, np.ndarray | None]:
    """The points and initial normals of the stratum `rows` (for one stratum the whole cloud's, not copied)."""
    if n_strata == 1:
        return points, initial
    return points[rows], None if initial is None else initial[rows]


def stratum_rows(n_points: int, n_strata: int) -> list[np.ndarray]:
    """The rows of each stratum: `estimators.strata.strata`, or all rows for one."""
    return strata(n_points, n_strata) if n_strata > 1 else [np.arange(n_points)]


def reconciled(points: np.ndarray, normals: np.ndarray, n_strata: int) -> np.ndarray:
    """The normals of the strata reconciled by `estimators.strata.consensus` (one stratum's as they are)."""
    if n_strata == 1:
        return normals
    with stage("consensus"):
        return consensus(points, normals, consensus_k(n_strata))


@dataclass(frozen=True)
class CloudLayout:
    """What every tile of one cloud (or stratum) takes from the whole of it: how the cloud is cut (own points per
    tile, margin), the length unit l_d, MFPS's candidacy and the smooth-point jet's noise (None where the method
    or a single tile does not need them)."""

    tile_points: int
    margin: float
    length: float
    candidacy: Candidacy | None = None
    noise: float | None = None

    def tiles(self, points: np.ndarray) -> list[Tile]:
        """The tiles of `points`, the cloud this layout was made for: the same every time."""
        return list(tiles(points, self.tile_points, self.margin))


def cloud_layout(points: np.ndarray, release: Release, method: str, given_initial: bool, scale: str = "spacing",
                 tile_points: int = TILE_POINTS, progress: bool = False) -> tuple[CloudLayout, list[Tile]]:
    """The layout of a cloud estimated as one stratum by `method`, and its tiles."""
    params = release.params
    runs_mfps = method == "mfps" or (method == "refinenet" and not given_initial)
    with stage("layout"):
        tree = build_tree(points)
        length = spacing_unit(points, release.spacing_ratio, tree) if scale == "spacing" else bbox_diagonal(points)
        margin = _margin(points, tree, params, method, runs_mfps, length) if len(points) > tile_points else 0.0
        del tree
        shared = CloudLayout(tile_points, margin, length)
        layout = shared.tiles(points)
        if len(layout) > 1 and runs_mfps:
            shared = replace(shared, candidacy=_candidacy(points, layout, params, progress))
        if len(layout) > 1 and method == "refinenet" and params.features.smooth_jet is not None:
            shared = replace(shared, noise=_noise(points, layout, progress))
    return shared, layout


def tile_normals(points: np.ndarray, tile: Tile, shared: CloudLayout, release: Release, method: str,
                 initial: np.ndarray | None = None, device: str = "auto", workers: int = 1,
                 progress: bool = False) -> np.ndarray:
    """The normals of a tile's own points (`tile.own`) of `points`, the cloud `shared` was made for; `initial`
    holds the whole cloud's initial normals, if given."""
    params = release.params
    sub, rows = points[tile.ids], tile.own_rows
    if method in ("pca", "jet"):
        with stage(method):
            return baseline_normals(sub, method, params.baselines, None)[rows]
    with stage("neighbours"):
        neighbours = neighbour_lists(sub, min(neighbour_width(params, method, initial is not None), len(sub)))
    if initial is not None:
        start = initial[tile.ids]
    else:
        with stage("mfps"):
            start = mfps_normals(sub, params.mfps, progress, workers, length=shared.length, ids=tile.ids,
                                 candidacy=shared.candidacy, neighbours=neighbours)
    if method == "mfps":
        return start[rows]
    features = compute_features(sub, start, params.features, progress, length=shared.length, centres=rows,
                                workers=workers, noise=shared.noise, neighbours=neighbours)
    neighbours = neighbours[rows, :params.patches.k] if params.patches.mode == "knn" else None
    return refine_normals(sub, features, release.cluster_model, release.networks, params.patches,
                          replace(params.inference, device=device), progress=progress, length=shared.length,
                          neighbours=neighbours)


def neighbour_width(params: Params, method: str, given_initial: bool) -> int:
    """How many neighbours the widest kNN list of `method`'s chain holds (MFPS's, the features' or the patches'):
    a tile's lists are found once, at this width, and every stage takes the first columns it needs."""
    widths = [] if given_initial else [params.mfps.scales[-1], params.mfps.k_bw]
    if method == "refinenet":
        widths += [features_width(params.features), params.patches.k if params.patches.mode == "knn" else 0]
    return max(widths, default=1)


#: The estimators the scan figure and table compare Refine-Net with, each with a release's settings.
COMPARED = ("pca", "jet", "mfps")


def compared_normals(points: np.ndarray, releases: dict[str, Release]) -> dict[str, np.ndarray]:
    """What the scan figure and table compare on one cloud, by method: PCA, Jet and MFPS with the settings of the
    first release, then each release's Refine-Net (keyed as `releases` names it) refining those MFPS normals, l_d
    from the point spacing."""
    first = next(iter(releases.values()))
    normals = {m: estimate_normals(points, first, m) for m in COMPARED}
    for name, release in releases.items():
        normals[name] = estimate_normals(points, release, "refinenet", initial=normals["mfps"])
    return normals


def _margin(points: np.ndarray, tree, params: Params, method: str, runs_mfps: bool, length: float) -> float:
    """How far beyond its own points a tile must reach for `method` to see whole neighbourhood chains."""
    def radius(k: int) -> float:
        return neighbour_distance(points, min(k, len(points) - 1), REACH_QUANTILE, tree)

    if method in ("pca", "jet"):
        return radius(neighbourhood_size(params.baselines, method, None))
    margin = MFPS_REACH * radius(params.mfps.k_bw) if runs_mfps else 0.0
    if method == "refinenet":
        f = params.features
        widest = max(f.hmp_k, params.patches.k, *(k for _, k in f.wide_normals))
        margin += f.r_f * length + FEATURE_REACH * radius(widest)
    return margin


def _candidacy(points: np.ndarray, layout: list[Tile], params: Params, progress: bool) -> Candidacy:
    """MFPS's whole-cloud candidacy from the surface variation of every tile's own points."""
    raw = np.empty(len(points))
    for tile in tqdm(layout, desc="MFPS candidacy", unit="tile", disable=not progress):
        raw[tile.own] = point_variation(points[tile.ids], params.mfps, tile.own_rows)
    return cloud_candidacy(raw, params.mfps)


def _noise(points: np.ndarray, layout: list[Tile], progress: bool) -> float:
    """The whole cloud's noise for `FeatureConfig.smooth_jet`, from the jets of every tile's own points."""
    residuals = np.empty(len(points))
    for tile in tqdm(layout, desc="noise", unit="tile", disable=not progress):
        residuals[tile.own] = point_noise(points[tile.ids], tile.own_rows)
    return float(np.median(residuals))

"""The one typed configuration: every block of params.yaml as a dataclass, composed into `Params`.

params.yaml is the only place that holds the values: no field here has a default (the few constants of a method
that params.yaml does not expose keep theirs, and the per-job seed and thread count are not params). The schema
beside this module is the only place of every range and choice: loading applies the active profile, checks every
value against it, which names the dotted key of the first bad one in a one-line error (`params.yaml:
baselines.pca_k: -3 is less than the minimum of 3`), then builds the blocks, whose own checks are only those a
schema cannot express (an even height-map size, which must be odd; scales out of order; a folder of normals that
does not exist).

This module sits on the lowest floor with `errors` and `atomic`: each library floor imports its block from
here, and a stage script loads `Params` without importing the floors it does not use.
"""

from __future__ import annotations

import copy
import functools
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import jsonschema
import yaml

from refinenet.errors import ParamsError, first_line

SCHEMA = Path(__file__).with_name("params.schema.yaml")
#: LibYAML's parser where PyYAML was built with it: the same documents, about ten times faster to read, which every
#: pipeline job pays for params.yaml and the schema.
_YAML_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


@functools.cache
def _schema() -> dict[str, Any]:
    return yaml.load(SCHEMA.read_text(), Loader=_YAML_LOADER)


#: Mappings whose keys are data (categories, list names), replaced whole by an override.
OPEN_MAPPINGS = frozenset({"test_lists", "test", "variant_budget"})
#: The training losses (the schema's `training.loss`), each of which `network.training` maps to its function.
LOSSES = tuple(_schema()["properties"]["training"]["properties"]["loss"]["enum"])
#: The Refine-Net variant that params.yaml describes as written; every other variant overrides it.
FULL = "full"
#: Full under `variant_budget`: the Refine-Net row of the tables of variants, trained and scored as they are.
REFERENCE = "reference"
#: The blocks a variant may override: those the per-variant steps (features, clustering, training, inference) read.
VARIANT_BLOCKS = ("seed", "features", "clustering", "network", "patches", "training", "inference")


@dataclass(frozen=True)
class PCPNetLists:
    """The list files of a PCPNet-format folder (`data.pcpnet`)."""

    train_list: str | None
    """Names of the training shapes; null: no training clouds (test only)."""
    test_lists: dict[str, str]
    """Table column -> list file; one test category per column."""


@dataclass(frozen=True)
class DataConfig:
    """Where a run's clouds come from (params.yaml `data`; README "Your own data")."""

    source: str
    """procedural | meshes | pcpnet | points."""
    path: str | None
    """Folder of the meshes, pcpnet and points sources."""
    split_folders: dict[str, str]
    """Sub-folder of `path` holding each split (meshes, points)."""
    n_points: int
    """Points sampled per shape or mesh (synthesised sources)."""
    max_shapes: int | None
    """At most this many shapes per split and category; None: all."""
    train_meshes: str | None
    """A folder in the meshes source's layout whose train split joins the training clouds of any source: real
    shapes beside the procedural ones (docs/accuracy.md); None: none."""
    pcpnet: PCPNetLists

    def __post_init__(self) -> None:
        if isinstance(self.pcpnet, dict):
            object.__setattr__(self, "pcpnet", PCPNetLists(**self.pcpnet))


@dataclass(frozen=True)
class NoiseConfig:
    """Gaussian noise levels in percent of l_d (params.yaml `noise`, docs/algorithm.md §1.2)."""

    train: tuple[float, ...]
    """Levels of every training shape."""
    test: dict[str, tuple[float, ...]]
    """Levels of the test shapes, per category."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "train", tuple(self.train))
        object.__setattr__(self, "test", {c: tuple(levels) for c, levels in self.test.items()})

    def levels(self, split: str, category: str) -> list[float]:
        if split == "train":
            return list(self.train)
        if category not in self.test:
            raise ParamsError(f"noise.test.{category}", "no test noise levels given for this category")
        return list(self.test[category])


@dataclass(frozen=True)
class BaselineConfig:
    """The baselines' settings in the paper's tables (params.yaml `baselines`)."""

    pca_k: int
    """PCA neighbourhood size K."""
    jet_k: int
    """Jet neighbourhood size K."""
    jet_degree: int
    """Degree of the fitted jet."""
    big_noise_k: int
    """K of both methods on BigNoise clouds: the paper uses 200 there, 100 elsewhere."""


@dataclass(frozen=True)
class MFPSConfig:
    """Parameters of MFPS (docs/algorithm.md §2, table A.7): the first five are params.yaml `mfps`; the rest are
    constants of the method with their released values."""

    scales: tuple[int, ...]
    """K: patch sizes in points (kNN including the centre). min(K) = k0 is also the PCA, bandwidth and
    orientation neighbourhood; [P] uses {50, 100, 150} for synthetic data, [C] {50, 100} for PCPNet."""
    trials: int
    """R: random planes per patch, each through the centre and 3 distinct random neighbours ([C])."""
    theta_t: float
    """Anisotropic angle in degrees between members of the fitting set A ([P] 60, [C] 45)."""
    a_max: int
    """Maximum size of the anisotropic set A ([C] 2, [P] unbounded)."""
    eta: Literal["code", "paper"]
    """Scale weight eta(k): "code" = exp(-((1 - k/k_max)/3)^2) as released, "paper" = linear from beta to 1."""
    beta: float = 0.9
    """Smallest weight of the paper's linear eta."""
    hist_bins: int = 50
    """Bins of the surface-variation histogram on [0, 1)."""
    tv_lambda: float = 0.5
    """Weight of the L1 trend filter that smooths the histogram."""
    flat_tol: float = 0.05
    """Knee rule: the filtered histogram has flattened when x[b-1] - x[b+1] is below this."""
    drop_tol: float = 0.05
    """Knee rule: the threshold bin must lie this far below the peak."""
    seed: int = 0
    """Seed of the random trials; the same seed gives bit-identical normals."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "scales", tuple(int(k) for k in self.scales))
        _check(list(self.scales) == sorted(set(self.scales)), "mfps.scales",
               f"must be increasing, got {list(self.scales)}")

    @property
    def k0(self) -> int:
        """Neighbourhood of PCA, surface variation, bandwidth and orientation: min(K)."""
        return self.scales[0]

    @property
    def k_bw(self) -> int:
        """Neighbourhood over which residuals are averaged into the bandwidth: 1.5 max(K), rounded down."""
        return 3 * self.scales[-1] // 2


def _check(ok: bool, key: str, problem: str) -> None:
    """A check the schema cannot express, reported under its dotted key (`Params.from_resolved` adds the file)."""
    if not ok:
        raise ParamsError(key, problem)


#: The estimators whose normals the pipeline computes and Refine-Net can refine (params.yaml `features.initial`).
INITIAL_ESTIMATORS = ("mfps", "pca", "jet")


@dataclass(frozen=True)
class FeatureConfig:
    """Everything that fixes a cloud's cached features (params.yaml `features`)."""

    r_f: float
    """Filter ball radius as a fraction of l_d: 0.03 code profile, 0.05 paper profile (§3)."""
    sigma_s: tuple[float, ...]
    """Spatial scales in units of R_f / 2 (outer loop of the filtered normals)."""
    sigma_r: tuple[float, ...]
    """Range scales (inner loop of the filtered normals)."""
    include_initial: bool
    """Keep the initial normal as the first of the X normals: X = 9 (synthetic, PCPNet); False: X = 8 (real scans)."""
    frame_mode: str
    """Sign convention of the per-point frames (§4): canonical (det +1, recommended) or faithful (the release's)."""
    hmp_size: int
    """m, the side of each height map."""
    hmp_k: int
    """The height-map half-extent is the distance to the k-th nearest neighbour (code profile)."""
    hmp_extent: float | None
    """Absolute height-map half-extent as a fraction of l_d (the paper profile's ball radius, e.g. 0.05); replaces
    hmp_k when set."""
    heights_dtype: str
    """Storage type of the height maps: float16 halves the cache (heights lie within +-0.3 in units of the extent,
    so the rounding error is at most 1.2e-4); float32 keeps them exact."""
    initial: str
    """The normals Refine-Net refines: an estimator of INITIAL_ESTIMATORS (MFPS, the paper's) or a folder holding
    any other estimator's, `<folder>/<split>/<category>/<name>.normals` per cloud ([P] "PCPNet-ms + Refine-Net")."""
    pca_k: int | None
    """Beyond the paper: append the PCA normal of this many neighbours to the X normals (X + 1, with its height
    map), so that the network sees a wide-neighbourhood fit where MFPS's fitting patches are wrong on smooth,
    curved surfaces (studies/README.md). None: the paper's X normals."""
    jet_k: int | None
    """Beyond the paper: append the degree-2 jet normal of this many neighbours after it (X + 1): on curved smooth
    surfaces a jet follows the curvature that biases a wide PCA fit. None: no jet normal."""
    smooth_jet: float | None
    """Beyond the paper: where a degree-2 jet of 100 neighbours fits them within this many times the cloud's noise,
    its normal replaces the initial normal before anything is computed from it (`estimators.smooth_jet`). None:
    the initial normals as they are."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "sigma_s", tuple(float(s) for s in self.sigma_s))
        object.__setattr__(self, "sigma_r", tuple(float(s) for s in self.sigma_r))
        _check(self.initial in INITIAL_ESTIMATORS or Path(self.initial).is_dir(), "features.initial",
               f"'{self.initial}' is neither one of {INITIAL_ESTIMATORS} nor an existing folder")
        _check(self.hmp_size % 2 == 1, "features.hmp_size", f"must be odd (a centre bin), got {self.hmp_size}")

    @property
    def wide_normals(self) -> tuple[tuple[str, int], ...]:
        """(estimator, k) of each wide-neighbourhood fit appended to the X normals, in their order."""
        return tuple((method, k) for method, k in (("pca", self.pca_k), ("jet", self.jet_k)) if k is not None)

    @property
    def n_normals(self) -> int:
        """X, the normals per point."""
        return len(self.sigma_s) * len(self.sigma_r) + int(self.include_initial) + len(self.wide_normals)


@dataclass(frozen=True)
class ClusteringConfig:
    """params.yaml `clustering`."""

    n_clusters: int
    """Kc, the number of clusters and so of networks."""
    restarts: int
    """k-means runs from different k-means++ seeds; the best (lowest within-cluster sum of squares) is kept."""
    max_samples: int | None
    """Training points (a seeded subset) used to fit PCA and k-means; None: all."""


@dataclass(frozen=True)
class NetworkParams:
    """params.yaml `network`: a preset and the two ablation choices. The input sizes are not set here: X and m
    come from the features block and the patch size from the patches block (`network.model.architecture`), so
    they always agree."""

    preset: str
    """release ([C] sizes) or paper ([P] sizes)."""
    features: str
    """Feature modules: full, normals, normals_points, normals_hmps."""
    connection: str
    """How a feature module refines a normal: weight, rot, trans, concat, residual."""
    output: str
    """normal ([P]: the network regresses the normal), correction (beyond the paper: it regresses a change of
    the initial normal, starting from no change) or blend (beyond the paper: a change of a learned weighted mean
    of the X input normals, starting from almost the initial normal)."""


@dataclass(frozen=True)
class PatchConfig:
    """The point-module neighbourhood (docs/algorithm.md §6; params.yaml `patches`)."""

    mode: str
    """knn (the release's, code profile) or ball (the paper's: random subset of a ball, padded with the centre)."""
    k: int
    """Neighbours per knn patch, self included; the patch is scaled by the distance to the k-th."""
    radius: float
    """Ball radius as a fraction of l_d (ball mode): 0.05 synthetic and PCPNet, 0.03 real scans."""
    max_points: int
    """Points per ball patch (ball mode): 300 synthetic and PCPNet, 500 real scans."""

    @property
    def size(self) -> int:
        """Points per patch the network receives: k (knn) or max_points (ball, padded with the centre)."""
        return self.k if self.mode == "knn" else self.max_points


@dataclass(frozen=True)
class TrainConfig:
    """Optimisation settings (docs/algorithm.md §9; params.yaml `training`), plus the per-job seed and threads."""

    optimizer: str
    """sgd (§9, with `momentum`) or adam (an option for short CPU profiles, typically with lr 1e-3)."""
    lr: float
    """Learning rate; the starting one under a schedule."""
    lr_schedule: str
    """constant ([P], [C]) or cosine: decayed per step to 0 at `max_epochs`, an option beyond the paper that lets
    a short training end on small steps instead of Adam's noise (benchmarks/results/training.md)."""
    momentum: float
    """SGD momentum (unused by adam)."""
    weight_decay: float
    """L2 penalty on all parameters, biases and BN included, as [C] applies it."""
    batch_size: int
    """Training and validation batch size; the last incomplete training batch is dropped (no BN on 1 sample).
    A cluster with fewer training points trains on one batch of all of them."""
    max_epochs: int
    """Upper bound on the epochs."""
    patience: int
    """Stop when the validation RMSE has not improved for this many epochs."""
    loss: str
    """mse (elementwise, [C]) or l1 (the loss ablation)."""
    val_fraction: float
    """Share of each cloud's points held out for validation, stratified by cluster ([P], §1.4)."""
    max_train_points_per_cloud: int | None
    """Random subset (drawn once) of each cloud's training points of the cluster, for CPU profiles; None: all."""
    device: str
    """auto (cuda when available), cpu or cuda."""
    precision: str
    """float32 ([P]) or bfloat16: the forward and backward passes compute in bfloat16 (autocast) while weights and
    optimiser state stay float32, 1.5x faster on a CPU with native bfloat16 (benchmarks/results/training.md);
    auto picks bfloat16 only there. Beyond the paper."""
    resample_points: bool
    """Draw the `max_train_points_per_cloud` subset anew every epoch: as many steps, more of the clouds' points
    seen (fewer of them shared by two seeds' trainings). Beyond the paper; no effect without a cap."""
    loader_workers: int
    """Processes that build batches (patches, frames, height maps) while the network trains; 0: the training
    process itself. A GPU needs several to stay busy (benchmarks/results/loader.md); results do not depend on it."""
    seed: int = 0
    """Seeds the initial weights, the validation split, the point caps, shuffling, patches and dropout."""
    threads: int | None = None
    """torch CPU threads; None leaves torch's default."""


@dataclass(frozen=True)
class InferenceConfig:
    """params.yaml `inference`."""

    batch_size: int
    """Points per network call; bounds the memory of the patches and height maps built for a batch."""
    device: str
    """auto (cuda when torch sees a GPU), cpu or cuda."""
    precision: str
    """Of the networks' feature modules, the point and height-map modules (`model.reduced_precision`): float32,
    bfloat16, or auto (bfloat16 on a CPU with native bfloat16)."""
    points: int | None
    """The pipeline's test clouds: refine only a seeded subset of this many points of each, which the tables then
    score (`data.clouds.scored_points`); None: every point. `variant_budget` sets it for the variants."""


@dataclass(frozen=True)
class EvaluationConfig:
    """params.yaml `evaluation`."""

    protocol: str
    """synthetic: pool the points of a category's clouds; pcpnet: the `.pidx` subset of each cloud, then the mean
    of the per-cloud values."""


@dataclass(frozen=True)
class DenoiseConfig:
    """params.yaml `denoise`: the point update of the denoising application (docs/algorithm.md §11) and the surface
    reconstructed from its result. [P] gives lambda, gamma and the iterations, not sigma nor the ball radius;
    `refinenet denoise` uses a release's values unless told others."""

    iterations: int
    lam: float
    """lambda: weight of the neighbours' own normal directions."""
    sigma: float
    """Width of the normal similarity w(n_i, n_j) = exp(-|n_i - n_j|^2 / sigma^2). With sign-aligned unit normals
    |n_i - n_j|^2 = 2 - 2|cos theta|: at 0.35, w = 0.5 at 17 deg and below 0.05 beyond 35 deg, so a neighbour across
    a sharp edge hardly pulls a point off its own face."""
    radius: float
    """Ball radius of the fixed neighbourhoods N_i, in l_d. The update shrinks curved surfaces by about
    (1 - lambda) r^2 / 12 per unit curvature and step, so a small ball is better where the cloud is dense enough
    (studies/results/denoise_radius.md)."""
    poisson_depth: int
    """Octree depth of the screened Poisson reconstruction (open3d)."""


@dataclass(frozen=True)
class FiguresConfig:
    """params.yaml `figures`: what the paper's figures show beyond the tables' settings."""

    variants: tuple[str, ...]
    """Refine-Net variants shown as columns of the normals figure after Refine-Net (fig_normals)."""
    scans: str | None
    """A folder of real scans for fig_real: point files (`data.io.POINT_FILE_SUFFIXES`) or meshes whose vertices
    are the points; None: the simulated scans (params.yaml `scanner`)."""
    scan_points: int | None
    """A seeded random subset of at most this many points per scan (the smoke profile's small figure)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "variants", tuple(self.variants))


@dataclass(frozen=True)
class ScannerConfig:
    """params.yaml `scanner`: the virtual depth camera of the simulated scans (docs/algorithm.md §1.5), the clouds
    of table_scans and, by default, of fig_real. A pipeline block like `variants`, outside `Params`: no release
    needs it (one stores it only within the whole resolved file). Lengths in metres, angles in radians unless named
    otherwise."""

    shapes: tuple[str, ...]
    """Shapes of the procedural catalogue (`data.shapes`) scanned, one scan each."""
    range_m: float
    """From the sensor to the shape's centre."""
    object_radius_m: float
    """The shape's radius in metres (the catalogue's shapes have radius 1): the scale of the scene."""
    pixel_rad: float
    """Angular step of the ray grid at the image centre."""
    sigma_m: float
    """Range noise at 1 m: a ray at range r metres has sigma = sigma_m * r^2."""
    disparity_step: float
    """Quantisation of the disparity 1/r, in 1/m (depth steps of about disparity_step * r^2); 0: none."""
    views: int
    """Viewpoints, evenly spaced in azimuth around the vertical axis."""
    elevation_deg: float
    """Height of the viewpoints above the shape's equator, as an angle seen from its centre."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "shapes", tuple(self.shapes))
        _check(self.range_m > self.object_radius_m, "scanner.range_m", "must exceed scanner.object_radius_m (the "
               "sensor would be inside the shape)")

    @classmethod
    def from_resolved(cls, params: dict[str, Any], source: str = "params.yaml") -> ScannerConfig:
        """The block of resolved params, checked as `Params.from_resolved` checks each of its blocks."""
        _check_block("scanner", params, source)
        return _built(lambda: cls(**params["scanner"]), source)


def _check_block(key: str, params: dict[str, Any], source: str) -> None:
    """The block `key` of resolved params is there and passes its part of the schema, or a one-line error."""
    if key not in params:
        raise ParamsError(key, "is missing", source)
    validate_block(key, params[key], source)


def _built(build: Callable[[], Any], source: str) -> Any:
    """What `build` makes of checked blocks, a dataclass's own check failing as a one-line error naming `source`."""
    try:
        return build()
    except ParamsError as err:
        raise ParamsError(err.key, err.problem, source) from None


@dataclass(frozen=True)
class Params:
    """Every setting of a run, one block per section of params.yaml (each documented in its dataclass)."""

    profile: str
    seed: int
    """The global seed; every job derives its own from it and the job's name (`data.noise.derive_seed`)."""
    data: DataConfig
    noise: NoiseConfig
    baselines: BaselineConfig
    mfps: MFPSConfig
    features: FeatureConfig
    clustering: ClusteringConfig
    network: NetworkParams
    patches: PatchConfig
    training: TrainConfig
    inference: InferenceConfig
    evaluation: EvaluationConfig
    denoise: DenoiseConfig
    figures: FiguresConfig

    @classmethod
    def from_resolved(cls, params: dict[str, Any], source: str = "params.yaml") -> Params:
        """Typed blocks from resolved params (one variant's, as `resolve` gives them or a release stores them): each
        block is checked against its part of the schema, then built, which checks what the schema cannot; either
        reports the first bad value under its dotted key."""
        blocks = {"data": DataConfig, "noise": NoiseConfig, "baselines": BaselineConfig, "mfps": MFPSConfig,
                  "features": FeatureConfig, "clustering": ClusteringConfig, "network": NetworkParams,
                  "patches": PatchConfig, "training": TrainConfig, "inference": InferenceConfig,
                  "evaluation": EvaluationConfig, "denoise": DenoiseConfig, "figures": FiguresConfig}
        for key in ("profile", "seed", *blocks):
            _check_block(key, params, source)
        typed = _built(lambda: {key: block(**params[key]) for key, block in blocks.items()}, source)
        return cls(profile=params["profile"], seed=params["seed"], **typed)


def deep_merge(base: dict[str, Any], override: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """`base` with `override` applied key by key; an override key absent from `base` is an error (a typo)."""
    merged = copy.deepcopy(base)
    for key, value in override.items():
        dotted = f"{prefix}{key}"
        if key not in base:
            raise ParamsError(dotted, "overrides a key that does not exist")
        if isinstance(value, dict) and isinstance(base[key], dict) and key not in OPEN_MAPPINGS:
            merged[key] = deep_merge(base[key], value, f"{dotted}.")
        else:
            merged[key] = copy.deepcopy(value)
    return merged


def get(params: dict[str, Any], dotted: str) -> Any:
    """The value at a dotted key, e.g. `get(p, "data.n_points")`."""
    value: Any = params
    for part in dotted.split("."):
        value = value[part]
    return value


def resolve(raw: dict[str, Any], source: str = "params.yaml", apply_profile: bool = True,
            variant: str = FULL) -> dict[str, Any]:
    """Validated parameters with the active profile's overrides applied (or, with `apply_profile` False, the
    file's own values: what the tests and benchmarks use as the library's settings), then those of `variant`
    (`variants` in params.yaml; `full` is the file as written)."""
    resolved = resolve_variants(raw, source, apply_profile)
    if variant not in resolved:
        raise ParamsError("variants", f"no variant '{variant}' (variants: {sorted(resolved)})", source)
    return resolved[variant]


def resolve_variants(raw: dict[str, Any], source: str = "params.yaml",
                     apply_profile: bool = True) -> dict[str, dict[str, Any]]:
    """`resolve` of every variant, full first."""
    if not isinstance(raw, dict):
        raise ParamsError("(top level)", "expected a mapping of keys to values", source)
    profile = raw.get("profile")
    profiles = raw.get("profiles") or {}
    if profile not in profiles:
        raise ParamsError("profile", f"'{profile}' is not one of the profiles {sorted(profiles)}", source)
    try:
        resolved = deep_merge(raw, {**profiles[profile], "profile": profile} if apply_profile else {}, "")
        every_profile = {name: deep_merge(raw, block, f"profiles.{name}.") for name, block in profiles.items()}
    except ParamsError as err:
        raise ParamsError(err.key, err.problem, source) from None
    validate(resolved, source)
    # Values the active profile masks, and those of the other profiles, are checked too, so that a bad value
    # is reported when it is written, not when a profile first uses it.
    validate(raw, source)
    for name, merged in every_profile.items():
        try:
            validate(merged, source)
        except ParamsError as err:
            raise ParamsError(f"profiles.{name}.{err.key}", err.problem, source) from None
    if REFERENCE in resolved["variants"]:
        raise ParamsError(f"variants.{REFERENCE}", "is reserved: full under variant_budget", source)
    written = [("variant_budget", raw["variant_budget"]),
               *((f"profiles.{name}.variant_budget", block["variant_budget"]) for name, block in profiles.items()
                 if "variant_budget" in (block or {}))]
    for where, budget in written:  # every budget as written, masked or not, reported under its own key
        _apply_overrides(resolved, budget, where, source)
    reference = _apply_overrides(resolved, resolved["variant_budget"], "variant_budget", source)
    every = {FULL: resolved, REFERENCE: reference,
             **{name: _apply_overrides(reference, resolved["variants"][name], f"variants.{name}", source)
                for name in resolved["variants"]}}
    for params in every.values():  # a variant's settings are its whole params; these blocks have served
        params.pop("variants")
        params.pop("variant_budget")
    return every


def _apply_overrides(resolved: dict[str, Any], overrides: dict[str, Any], where: str, source: str) -> dict[str, Any]:
    """`resolved` with the overrides written at `where` (a variant's, or the budget), checked: only the per-variant
    blocks, valid values."""
    for key in overrides:
        if key not in VARIANT_BLOCKS:
            raise ParamsError(f"{where}.{key}", f"a variant may override only {', '.join(VARIANT_BLOCKS)}", source)
    try:
        merged = deep_merge(resolved, overrides, f"{where}.")
    except ParamsError as err:
        raise ParamsError(err.key, err.problem, source) from None
    for key in sorted(overrides):  # the other blocks are `resolved`'s, valid already
        try:
            validate_block(key, merged[key], source)
        except ParamsError as err:
            raise ParamsError(f"{where}.{err.key}", err.problem, source) from None
    return merged


@functools.cache
def _validator() -> jsonschema.Draft202012Validator:
    return jsonschema.Draft202012Validator(_schema())


def validate(params: dict[str, Any], source: str = "params.yaml") -> None:
    """Check every value against the JSON schema; report the first problem with its dotted key."""
    errors = sorted(_validator().iter_errors(params), key=lambda e: list(e.path))
    if errors:
        err = errors[0]
        key = ".".join(str(p) for p in err.path) or "(top level)"
        raise ParamsError(key, err.message, source)


@functools.cache
def _block_validator(block: str) -> jsonschema.Draft202012Validator:
    return jsonschema.Draft202012Validator({**_schema()["properties"][block], "definitions": _schema()["definitions"]})


def validate_block(block: str, values: dict[str, Any], source: str) -> None:
    """Check one block's values (e.g. given on a command line, or a variant's) against its part of the JSON
    schema."""
    for err in sorted(_block_validator(block).iter_errors(values), key=lambda e: list(e.path))[:1]:
        raise ParamsError(".".join([block, *map(str, err.path)]), err.message, source)


def read_raw(path: str | Path = "params.yaml") -> dict[str, Any]:
    """The file as written, for the keys that Snakemake and DVC track."""
    path = Path(path)
    try:
        return yaml.load(path.read_text(), Loader=_YAML_LOADER)
    except (OSError, ValueError, yaml.YAMLError) as err:  # ValueError: not UTF-8 text
        raise ParamsError("(file)", f"cannot be read as YAML ({first_line(err)})", str(path)) from None


def load(path: str | Path = "params.yaml", apply_profile: bool = True, variant: str = FULL) -> Params:
    """Read, resolve and validate a params file into `Params` (of one Refine-Net variant)."""
    return Params.from_resolved(resolve(read_raw(path), str(path), apply_profile, variant), str(path))

"""The pipeline's steps, declared once for both Snakemake and DVC.

A step has one name everywhere: its DVC stage and its Snakemake rule carry it, and its family (the step's name
without an instance suffix such as `_train` or `_synthetic`) names its rule file `workflow/rules/FAMILY.smk`
and its stage script `stages/FAMILY.py`. Each `Step` lists the params keys it reads, its code, and the files it
reads and writes. The Snakefile takes rule params and code inputs from here; `dvc.yaml` is generated from here
(`python -m refinenet.pipeline.workflow`), and a test checks the two agree, so changing a key reruns exactly
the same steps in both tools.
"""

from __future__ import annotations

import argparse
import functools
import os
import sys
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import yaml

from refinenet import config
from refinenet.config import Params
from refinenet.data.clouds import SPLITS, CloudSpec, list_clouds
from refinenet.errors import ParamsError
from refinenet.estimators.baselines import METHODS as BASELINES
from refinenet.estimators.mfps import METHODS as MFPS_METHODS
from refinenet.evaluation.table import METHOD_NAMES

DVC_FILE = Path("dvc.yaml")
REGENERATE = "run `python -m refinenet.pipeline.workflow` to regenerate it from params.yaml"
REFINENET = "refinenet"
FULL = config.FULL
REFERENCE = config.REFERENCE

#: File layout, as Snakemake patterns: `{cloud}` is a cloud's key `<split>/<category>/<name>`, `{variant}` a
#: Refine-Net variant (params.yaml `variants`; `full` is the default Refine-Net).
CLOUD = "results/clouds/{cloud}.npz"
FEATURES = "results/features/{variant}/{cloud}.npz"
NORMALS = "results/normals/{method}/{cloud}.npy"
#: Refine-Net's output is the PCPNet text format, the form users compare with other methods.
REFINED = f"results/normals/{REFINENET}/{{variant}}/{{cloud}}.normals"
CLUSTER_MODEL = "results/clusters/{variant}/model.npz"
MODEL_DIR = "results/models/{variant}"
NETWORK = f"{MODEL_DIR}/cluster_{{cluster}}"
HISTORY_DIR = "results/history/{variant}"
HISTORY = f"{HISTORY_DIR}/cluster_{{cluster}}.csv"
#: Resumable training state, outside every step's outputs so that neither tool clears it before a rerun.
CHECKPOINT_DIR = "results/checkpoints/{variant}"
#: The shipped release (`network.release`): committed with the package, so it is not DVC-cached.
RELEASE = "src/refinenet/shipped"
TABLE_FILES = {"csv": "reports/{table}.csv", "tex": "reports/{table}.tex", "per_cloud": "reports/per_cloud/{table}.csv"}
TABLE_METRICS = "reports/metrics/{table}.json"
#: Each per-cloud job's log and Snakemake benchmark file (wall seconds, peak memory), by step: a method
#: (`mfps`) or a per-variant family and its variant (`features/full`).
JOB_LOG = "logs/{step}/{cloud}.log"
JOB_BENCHMARK = "logs/{step}/{cloud}.benchmark.tsv"
#: [P] Table time, from the job benchmark files (`pipeline.timing`): it differs from run to run.
TIME_FILES = {"csv": "reports/table_time.csv", "tex": "reports/table_time.tex",
              "per_cloud": "reports/per_cloud/table_time.csv", "metrics": "reports/metrics/table_time.json"}
#: The line plot of a sweep table (e.g. the Kc sweep of fig:cluster).
TABLE_PLOT = "reports/{table}.png"


def fill(pattern: str, **values: object) -> str:
    """`pattern` with the given wildcards filled in and the others left as Snakemake wildcards."""
    class Keep(dict):
        def __missing__(self, key: str) -> str:
            return f"{{{key}}}"
    return pattern.format_map(Keep(values))


def clouds(params: Params, split: str | None = None) -> list[CloudSpec]:
    """The run's clouds (optionally of one split)."""
    return [c for c in list_clouds(params.data, params.noise) if split in (None, c.split)]


def first_test_clouds(params: Params) -> dict[str, str]:
    """The first test cloud of each category, category -> key."""
    first: dict[str, str] = {}
    for c in clouds(params, "test"):
        first.setdefault(c.category, c.key)
    return first


def check_keys(params: Params) -> list[str]:
    """One test cloud per category (the first): where the release measures what half precision changes."""
    return list(first_test_clouds(params).values())


def data_line(params: Params) -> str:
    """The profile and the data of a run, as table captions and figure footers name them."""
    d = params.data
    return (f"Profile {params.profile}; data: {d.source}" + (f" ({d.path})" if d.path else "")
            + f", {d.n_points} points per cloud.")


def gpus(device: str) -> int:
    """The `gpu` resource of a rule whose params name `device`: one GPU for cuda and auto, none for cpu. A cluster
    executor turns it into a GPU request (SLURM: --gpus=1); a local run caps concurrent GPU jobs with
    `--resources gpu=N`; rules without it never wait for a GPU."""
    return 0 if device == "cpu" else 1


def refinenet(variant: str) -> str:
    """The method name of a Refine-Net variant in tables: `refinenet` for full, `refinenet/<variant>` otherwise."""
    return REFINENET if variant == FULL else f"{REFINENET}/{variant}"


def variant_of(method: str) -> str | None:
    """The variant of a Refine-Net method name; None for the other estimators."""
    if method == REFINENET:
        return FULL
    return method.removeprefix(f"{REFINENET}/") if method.startswith(f"{REFINENET}/") else None


@dataclass(frozen=True)
class Table:
    """A results table of the paper: which methods are its rows and which metrics its columns."""

    methods: tuple[str, ...]
    metrics: tuple[str, ...]
    title: str
    labels: tuple[tuple[str, str], ...] = ()
    """Row names of this table where they differ from the methods' usual names (e.g. full as Refine-Net-Weight)."""
    sweep: tuple[str, str] | None = None
    """(params key, symbol): the rows are variants that differ in this key; each is labelled and ordered by its
    value (the first of equal values kept), and the Average mean error is plotted against it."""
    protocol: str | None = None
    """How categories aggregate (`evaluation.protocol`'s values): fixed by the table, or None for the run's."""

    @staticmethod
    def files(name: str, table: Table | None = None) -> dict[str, str]:
        """The table's outputs by kind: csv, tex, per_cloud, its metrics record and, for a sweep, the plot."""
        files = {**{kind: path.format(table=name) for kind, path in TABLE_FILES.items()},
                 "metrics": TABLE_METRICS.format(table=name)}
        if table is not None and table.sweep:
            files["plot"] = TABLE_PLOT.format(table=name)
        return files

    @property
    def variants(self) -> list[str]:
        return [v for v in map(variant_of, self.methods) if v is not None]


#: Normal estimators and the params blocks that configure each (their values are named in table captions).
METHODS = {**{m: ("baselines",) for m in BASELINES}, **{m: ("mfps",) for m in MFPS_METHODS},
           REFINENET: ("mfps", "features", "clustering", "network", "patches", "training")}
_SYNTHETIC = (*BASELINES, *MFPS_METHODS, REFINENET)
#: Rows of the ablation table ([P] table:ablation_results), after MFPS and simple MFPS.
ABLATION = (("normals", "normals"), ("normals_hmps", "normals&HMPs"), ("normals_points", "normals&points"),
            ("concat", "concat"), ("residual", "residual"), ("rot", "Refine-Net-Rot"), ("trans", "Refine-Net-Trans"),
            (REFERENCE, "Refine-Net-Weight"))
TABLES = {
    "table_baselines": Table(BASELINES, ("mean", "rmse"), "Baselines: unoriented angular error (degrees)"),
    "table_synthetic": Table(_SYNTHETIC, ("mean", "rmse"), "Synthetic benchmark: unoriented angular error (degrees)"),
    "table_synthetic_pgp": Table(_SYNTHETIC, ("pgp5", "pgp10"),
                                 "Synthetic benchmark: proportion of good points (error below 5 and 10 degrees)"),
    "table_ablation": Table((*MFPS_METHODS, *(refinenet(v) for v, _ in ABLATION)), ("mean", "rmse"),
                            "Ablation study: unoriented angular error (degrees)",
                            labels=tuple((refinenet(v), label) for v, label in ABLATION)),
    "table_loss": Table((refinenet("l1"), refinenet("l2")), ("mean", "rmse"),
                        "Training loss, L1 against L2: unoriented angular error (degrees)",
                        labels=((refinenet("l1"), "L1"), (refinenet("l2"), "L2"))),
    "table_initial": Table(("pca", refinenet("pca_init"), "jet", refinenet("jet_init"), "mfps", refinenet(REFERENCE),
                            refinenet("pca_input")),
                           ("mean", "rmse", "pgp10"),
                           "Refine-Net on other initial normals: unoriented angular error (degrees) and PGP10",
                           labels=((refinenet("pca_init"), "PCA + Refine-Net"),
                                   (refinenet("jet_init"), "Jet + Refine-Net"),
                                   (refinenet(REFERENCE), "MFPS + Refine-Net"),
                                   (refinenet("pca_input"), "MFPS + Refine-Net (PCA K = 100 input)"))),
    "table_pcpnet": Table((*BASELINES, *MFPS_METHODS[:1], REFINENET), ("rmse",),
                          "PCPNet benchmark: RMSE (degrees) on each shape's scored points (its .pidx subset), "
                          "averaged over the shapes of a column",
                          protocol="pcpnet"),
    "table_clusters": Table(tuple(refinenet(v) for v in (REFERENCE, "kc1", "kc2", "kc3", "kc5", "kc6", "kc8")),
                            ("mean", "rmse"), "Number of clusters Kc: unoriented angular error (degrees)",
                            sweep=("clustering.n_clusters", "Kc")),
    "table_seeds": Table(tuple(refinenet(v) for v in (REFERENCE, "seed2023", "seed2024")), ("mean", "rmse"),
                         "Refine-Net under three seeds of its clustering, training and inference: unoriented angular "
                         "error (degrees)", sweep=("seed", "seed")),
}


#: [P] Table network_architecture: the networks whose height-map modules it shows, with their column titles.
ARCHITECTURE = {FULL: "Refine-Net", "normals_hmps": "Ablation (normals&HMPs)"}
ARCHITECTURE_FILES = {"csv": "reports/table_architecture.csv", "tex": "reports/table_architecture.tex",
                      "layers": "reports/table_architecture_layers.csv"}


COMPARISON_FILES = {"md": "reports/paper_comparison.md", "tex": "reports/paper_comparison.tex"}

#: [P] fig:syn and fig:insight: normals as RGB and error heat maps of chosen test clouds (`evaluation.figures`),
#: one column per method.
FIGURE_NORMALS = {"png": "reports/figures/normals_and_errors.png", "pdf": "reports/figures/normals_and_errors.pdf"}
FIGURE_METHODS = (*BASELINES, "mfps", REFINENET)
#: The categories of the figure's clouds, as in fig:syn: a CAD shape with sharp edges and one with rich detail.
FIGURE_CATEGORIES = ("SharpFeature", "RichFeature")
#: [P] fig:cluster: the first figure cloud coloured by cluster for Kc = 2 (variant kc2) and Kc = 4 (full), beside
#: the Kc curve of table_clusters.
FIGURE_CLUSTERS = {"png": "reports/figures/clusters.png", "pdf": "reports/figures/clusters.pdf"}
CLUSTER_FIGURE_VARIANTS = ("kc2", FULL)
#: [P] fig:loss2: one shape at increasing noise, each point blue where L1 (variant l1) gives the lower error and red
#: where L2 (variant l2, mse) does.
FIGURE_LOSS = {"png": "reports/figures/l1_against_l2.png", "pdf": "reports/figures/l1_against_l2.pdf"}
#: Training loss and validation error per epoch of every cluster, one figure per trained variant.
FIGURE_TRAINING_DIR = "reports/figures/training"
FIGURE_TRAINING = f"{FIGURE_TRAINING_DIR}/{{variant}}.png"
#: [P] fig:real_boy and fig:outdoor: normals as RGB on the real scans of params.yaml `figures.scans` (no truth) by
#: PCA, Jet, MFPS and Refine-Net in the paper's real-data setting X = 8 (the variant REAL_VARIANT), through the
#: chain of `refinenet normals` (radii from the point spacing, `cli.estimate`).
FIGURE_REAL = {"png": "reports/figures/real_scans.png", "pdf": "reports/figures/real_scans.pdf"}
REAL_VARIANT = "x8"
REAL_METHODS = (*BASELINES, "mfps", REFINENET)


#: [P] §Application (docs/algorithm.md §11): every test cloud with a known clean surface denoised with the normals of
#: each method, a record of its points and distances to the true surface per cloud, a table of the distances and a
#: figure of the denoised points and surfaces.
DENOISED = "results/denoised/{cloud}.npz"
DENOISE_METHODS = ("pca", "mfps", REFINENET)
DENOISE_INPUT = "input"
DENOISE_NAMES = {DENOISE_INPUT: "noisy input", **METHOD_NAMES}
DENOISE_TABLE = "table_denoise"
FIGURE_DENOISE = {"png": "reports/figures/denoising.png", "pdf": "reports/figures/denoising.pdf"}


@dataclass(frozen=True)
class TableEntry:
    """A table of the page: its CSV (rendered), its LaTeX (whose caption it shows) and every file to link."""

    name: str
    csv: str
    tex: str | None
    links: dict[str, str]


@dataclass(frozen=True)
class FigureEntry:
    """A figure of the page: the PNG shown, what it shows, and every file to link (e.g. the PDF)."""

    name: str
    png: str
    caption: str
    links: dict[str, str]


#: The page with every table and figure (`evaluation.report`), and one LaTeX document of every table; report_pdf
#: compiles that document where pdflatex is installed.
REPORT_FILES = {"html": "reports/index.html", "tex": "reports/tables.tex"}
TABLES_PDF = "reports/tables.pdf"
REPORT_DIR = "reports"
#: Files that hold the timings of the run that made them (table_time and the reports that include it): they differ
#: from run to run.
TIMED_FILES = (*TIME_FILES.values(), *REPORT_FILES.values(), TABLES_PDF)


#: The main job (`snakemake main`, scripts/run.sh): the synthetic benchmark's tables and the shipped release, within
#: the default profile's budget. The ablation tables, each trained variant by variant, are built by the full run.
MAIN = ("table_baselines", "table_synthetic", "table_synthetic_pgp", "release")


@dataclass(frozen=True)
class Step:
    """One pipeline step: a DVC stage and the Snakemake rule of the same name that makes its files."""

    name: str
    family: str
    """The rule file and stage script shared by the instances of a step (e.g. clouds_train and clouds_test, or
    training and training_l1)."""
    modules: tuple[str, ...]
    """Library modules (dotted, below `refinenet`) that the stage script imports."""
    keys: tuple[str, ...]
    """params.yaml keys the step reads; a change of any of them reruns it in both tools."""
    deps: tuple[str, ...]
    outs: tuple[str, ...]
    targets: Callable[[], list[str]]
    """Every file the step makes for the run's params (listing the clouds only when asked)."""
    metrics: tuple[str, ...] = ()
    plots: tuple[str, ...] = ()
    variant: str = FULL
    """The Refine-Net variant whose settings the step runs with."""
    split: str | None = None
    """The one split whose clouds the step covers, where its instances divide the work by split."""
    needs: str | None = None
    """A program the step needs beyond the Python environment; Snakemake's default target skips the step, with a
    message, where it is not installed."""

    @property
    def code(self) -> list[str]:
        """Files whose change must rerun the step: the Snakefile and shared rules, its rule file and stage script,
        and every library module it imports."""
        return ["workflow/Snakefile", "workflow/rules/common.smk", f"workflow/rules/{self.family}.smk",
                "stages/__init__.py", f"stages/{self.family}.py",
                *(f"src/refinenet/{m.replace('.', '/')}.py" for m in dict.fromkeys(self.modules))]


#: Library modules the stage scripts import, in groups (a test checks every script against its step's list).
_STAGE = ("config", "errors", "atomic", "threads", "allocator", "pipeline.stage")
_DATA = ("data.clouds", "data.shapes", "data.meshes", "data.noise", "data.io")
_GEOMETRY = ("geometry.neighbors", "geometry.grid_knn", "geometry.ball")
_FEATURES = ("features.cache", "features.filtering", "features.heightmaps", "geometry.frames", *_GEOMETRY, "data.io",
             "data.noise", "estimators.baselines", "estimators.smooth_jet", "data.shapes", "data.meshes")
_NETWORK = (*_FEATURES, "network.clustering", "network.dataset", "network.model", "network.devices", "network.training",
            "features.patches", "evaluation.metrics")
_TABLE = ("evaluation.table", "evaluation.metrics", "evaluation.plots", "pipeline.workflow", "estimators.baselines",
          "estimators.mfps", *_DATA, *_GEOMETRY)
#: The figure script's (one for the fig steps; the real-scan figure runs the chain of `refinenet normals`).
_FIG = ("evaluation.figures", "evaluation.render", "evaluation.denoise", "geometry.orientation", "cli.estimate",
        "estimators.strata", "network.inference", "network.release", "geometry.scale", "geometry.tiles", *_NETWORK,
        *_TABLE, *_STAGE)

#: How a table caption names a Refine-Net output beyond the paper's (NetworkConfig.output).
OUTPUT_CAPTIONS = {"correction": "output a correction of the initial normal, ",
                   "blend": "output a correction of a learned weighted mean of the input normals, "}
#: The keys that fix the network (`network.model.architecture`): X and m come from the features block.
_ARCHITECTURE = ("features.sigma_s", "features.sigma_r", "features.include_initial", "features.hmp_size",
                 "features.pca_k", "features.jet_k", "network", "patches")
#: The steps run once per Refine-Net variant, the keys each reads, and the steps whose files it reads. A variant
#: has its own instance of a step when its overrides reach the step's keys or it has one of an upstream step;
#: otherwise it uses full's files.
VARIANT_STEPS = {
    "features": (("features",), ()),
    "clustering": (("clustering", "seed"), ("features",)),
    "training": ((*_ARCHITECTURE, "training", "seed"), ("features", "clustering")),
    "inference": ((*_ARCHITECTURE, "inference", "seed"), ("features", "clustering", "training")),
}


def _leaves(tree: Any, prefix: str = "") -> list[str]:
    if not isinstance(tree, dict) or not tree:
        return [prefix.rstrip(".")]
    return [leaf for key, value in tree.items() for leaf in _leaves(value, f"{prefix}{key}.")]


def _overlaps(a: str, b: str) -> bool:
    return a == b or a.startswith(f"{b}.") or b.startswith(f"{a}.")


def override_keys(raw: dict[str, Any], variant: str) -> set[str]:
    """The dotted keys a variant overrides, in params.yaml's `variants` and `variant_budget` (which every variant
    but full takes) and in any profile's."""
    if variant == FULL:
        return set()
    sources = [raw, *((raw.get("profiles") or {}).values())]
    blocks = [((s or {}).get("variants") or {}).get(variant) for s in sources]
    blocks += [(s or {}).get("variant_budget") for s in sources]
    return {leaf for block in blocks if block for leaf in _leaves(block)}


def owners(raw: dict[str, Any], variant: str) -> dict[str, str]:
    """For each per-variant step, the variant whose files `variant` uses: itself or full. Decided by the keys
    written, not their values, so that the pipeline (and dvc.yaml) is the same whichever profile is active."""
    overridden = override_keys(raw, variant)
    own: dict[str, str] = {}
    for family, (keys, upstream) in VARIANT_STEPS.items():
        reached = any(_overlaps(k, o) for k in keys for o in overridden)
        own[family] = variant if reached or any(own[u] == variant for u in upstream) else FULL
    return own


class Pipeline:
    """The steps of one params file: every Refine-Net variant's settings, which files each variant owns, and one
    `Step` per DVC stage and Snakemake rule."""

    def __init__(self, raw: dict[str, Any], source: str = "params.yaml"):
        self.raw = raw
        self.resolved = config.resolve_variants(raw, source)
        """Each variant's resolved params (dotted keys apply: `config.get(resolved[v], key)`)."""
        self.params = {v: _typed(v, resolved, source) for v, resolved in self.resolved.items()}
        self.full = self.params[FULL]
        real = [REAL_VARIANT] if self.full.figures.scans else []
        for name, variants in [*((n, t.variants) for n, t in TABLES.items()), ("table_architecture", ARCHITECTURE),
                               ("fig_real", real)]:
            for v in variants:
                if v not in self.params:
                    raise ParamsError("variants", f"{name} needs the variant '{v}', which is not defined", source)
        for v in self.full.figures.variants:
            if v not in self.params:
                raise ParamsError("figures.variants", f"'{v}' is not a variant (variants: {sorted(self.params)})",
                                  source)
        self.scored = {v for t in TABLES.values() for v in t.variants} | set(self.full.figures.variants)
        """The variants whose normals of the test clouds a table or the normals figure shows: only these have
        test-cloud features and inference (x8 serves the real-scan figure alone)."""
        for name, methods in [*((n, t.methods) for n, t in TABLES.items()), ("fig_normals", self.figure_methods())]:
            self.scored_subset(methods, f"{name}: ")
        self.owners = {v: owners(raw, v) for v in self.params}
        self.steps: dict[str, Step] = {s.name: s for s in self._steps()}

    def scored_subset(self, methods: tuple[str, ...], where: str = "") -> int | None:
        """How many points of each test cloud the rows of a table (or the panels of a figure) are scored on: the
        `inference.points` of its Refine-Net variants (None: all). Every row scores the same points, so the variants
        that refine a subset must agree on its size; the others refined every point, any subset included."""
        sizes = {self.params[v].inference.points for v in map(variant_of, methods) if v is not None} - {None}
        if len(sizes) > 1:
            raise ParamsError("inference.points", f"{where}its Refine-Net variants refine subsets of different sizes "
                              f"{sorted(sizes)}; a table scores one subset")
        return next(iter(sizes), None)

    @functools.cached_property
    def clouds(self) -> list[CloudSpec]:
        return clouds(self.full)

    def owner(self, variant: str, family: str) -> str:
        return self.owners[variant][family]

    def family(self, name: str) -> list[Step]:
        """The instances of one step family, full's first."""
        return [s for s in self.steps.values() if s.family == name]

    def keys(self, split: str | None = None) -> list[str]:
        return [c.key for c in self.clouds if split in (None, c.split)]

    def normals_path(self, method: str, cloud: str) -> str:
        """Estimated normals of the cloud with key `cloud` (a Refine-Net variant's from the variant that owns them)."""
        variant = variant_of(method)
        if variant is None:
            return NORMALS.format(method=method, cloud=cloud)
        return REFINED.format(variant=self.owner(variant, "inference"), cloud=cloud)

    def normals_dir(self, method: str, split: str = "test") -> str:
        """The folder of a method's normals of one split (a step's dependency)."""
        return os.path.dirname(self.normals_path(method, f"{split}/x"))

    def initial_path(self, variant: str, cloud: str) -> str:
        """The normals the features of `variant` start from, for the cloud with key `cloud`."""
        initial = self.params[variant].features.initial
        if initial in config.INITIAL_ESTIMATORS:
            return self.normals_path(initial, cloud)
        return f"{initial}/{cloud}.normals"

    @property
    def trained(self) -> list[str]:
        """The variants with networks of their own (full's first)."""
        return [v for v in self.params if self.owner(v, "training") == v]

    def denoise_keys(self) -> list[str]:
        """The test clouds the denoising application covers: those synthesised from a surface (a procedural shape or
        a mesh), against which distances are measured."""
        return [c.key for c in self.clouds if c.split == "test" and c.noise is not None]

    def denoise_figure_key(self) -> str:
        """The cloud of the denoising figure: the normals figure's first cloud, if the application covers it."""
        keys = self.denoise_keys()
        return next((k for k in self.figure_keys() if k in keys), keys[0])

    def figure_methods(self) -> tuple[str, ...]:
        """The columns of the normals figure: FIGURE_METHODS, then the variants of params.yaml `figures.variants`."""
        return tuple(dict.fromkeys((*FIGURE_METHODS, *map(refinenet, self.full.figures.variants))))

    def figure_keys(self) -> list[str]:
        """The test clouds of the normals figure: the first of each FIGURE_CATEGORIES category, or (a source
        without them) the first test cloud."""
        first = first_test_clouds(self.full)
        return [first[c] for c in FIGURE_CATEGORIES if c in first] or [next(iter(first.values()))]

    def reported(self) -> tuple[list[TableEntry], list[FigureEntry]]:
        """Every table and figure of the report page, paths relative to the page's folder."""
        def rel(paths: dict[str, str]) -> dict[str, str]:
            return {kind: os.path.relpath(path, REPORT_DIR) for kind, path in paths.items()}
        denoise = bool(self.denoise_keys())
        tables = [TableEntry(name, files["csv"], files["tex"], files)
                  for name, files in [*((n, rel(Table.files(n))) for n in TABLES),
                                      *([(DENOISE_TABLE, rel(Table.files(DENOISE_TABLE)))] if denoise else []),
                                      ("table_time", rel(TIME_FILES)), ("table_architecture", rel(ARCHITECTURE_FILES))]]
        figures = [
            FigureEntry("normals_and_errors", **_figure(rel(FIGURE_NORMALS)), caption=(
                "[P] fig:syn / fig:insight: normals as RGB and unoriented angular-error heat maps of "
                f"{', '.join(map(figure_name, self.figure_methods()))} on the first test cloud of "
                f"{' and '.join(FIGURE_CATEGORIES)}; each panel's mean error in its title.")),
            *([FigureEntry("real_scans", **_figure(rel(FIGURE_REAL)), caption=(
                "[P] fig:real_boy / fig:outdoor: normals as RGB of "
                f"{', '.join(METHOD_NAMES[m] for m in REAL_METHODS)} (X = 8, variant {REAL_VARIANT}) on the real "
                f"scans of {self.full.figures.scans} (no ground truth), radii from the point spacing."))]
              if self.full.figures.scans else []),
            FigureEntry("clusters", **_figure(rel(FIGURE_CLUSTERS)), caption=(
                "[P] fig:cluster: a test cloud coloured by cluster for "
                f"{' and '.join(f'variant {v}' for v in CLUSTER_FIGURE_VARIANTS)}, beside the Kc curve.")),
            *([FigureEntry("denoising", **_figure(rel(FIGURE_DENOISE)), caption=(
                "[P] fig:block: a test cloud denoised with the normals of "
                f"{', '.join(METHOD_NAMES[m] for m in DENOISE_METHODS)} (top: points coloured by their distance to "
                "the true surface; bottom: screened Poisson surfaces), beside the noisy input and the true surface."))]
              if denoise else []),
            FigureEntry("l1_against_l2", **_figure(rel(FIGURE_LOSS)), caption=(
                "[P] fig:loss2: one test shape at increasing noise, each point blue where Refine-Net trained with L1 "
                "has the lower error and red where the L2 (mse) network has; the share of blue points in each title.")),
            *(FigureEntry(name, **_figure(rel({"png": Table.files(name, table)["plot"]})),
                          caption=f"The {table.sweep[1]} sweep: Average mean error against {table.sweep[1]} ({name}).")
              for name, table in TABLES.items() if table.sweep),
            *(FigureEntry(f"training_{v}", **_figure(rel({"png": FIGURE_TRAINING.format(variant=v)})),
                          caption=f"Training loss and validation error per epoch of every cluster of variant {v}.")
              for v in self.trained),
        ]
        return tables, figures

    def loss_figure_keys(self) -> list[str]:
        """The test clouds of the L1/L2 figure: the first figure cloud's shape at each of its noise levels, least
        noise first (the first figure cloud alone where the data gives no shape at several levels)."""
        first = next(c for c in self.clouds if c.key == self.figure_keys()[0])
        levels = [c for c in self.clouds if c.split == "test" and c.origin == first.origin and c.noise is not None]
        return [c.key for c in sorted(levels, key=lambda c: c.noise)] or [first.key]

    def rows(self, table: Table) -> dict[str, str]:
        """The table's rows, method -> row name. A sweep table's rows are named and ordered by the swept value,
        the first row of equal values kept (in the smoke profile kc2 repeats full's Kc = 2)."""
        if not table.sweep:
            return {m: dict(table.labels).get(m, METHOD_NAMES.get(m, m)) for m in table.methods}
        key, symbol = table.sweep
        first = {self.swept(m, key): m for m in reversed(table.methods)}
        return {first[value]: f"{symbol} = {value}" for value in sorted(first)}

    def swept(self, method: str, key: str) -> Any:
        """The value of a dotted params key for a Refine-Net variant's method."""
        return config.get(self.resolved[variant_of(method)], key)

    def caption(self, table: Table) -> str:
        """A table caption naming the profile, the data, the settings of every method in the table and what each
        variant changes."""
        params, methods = self.full, table.methods
        b, m = params.baselines, params.mfps
        parts = [f"{table.title}, {self.protocol(table)} protocol.", data_line(params)]
        if set(BASELINES) & set(methods):
            parts.append(f"PCA/Jet K = {b.pca_k}/{b.jet_k} ({b.big_noise_k} for BigNoise), jet degree {b.jet_degree}.")
        if set(MFPS_METHODS) & set(methods):
            parts.append(f"MFPS K = {{{', '.join(map(str, m.scales))}}}, R = {m.trials}, "
                         f"theta_t = {m.theta_t} deg, |A| <= {m.a_max}, eta = {m.eta}.")
        # Every variant is reference (full under the variant budget) with its changes, so a table of variants
        # names reference's settings, whether or not reference is one of its rows (table_loss's are l1 and l2).
        compared = set(table.variants) - {FULL}
        if table.variants:
            reference = self.params[REFERENCE if compared else FULL]
            f, n, t, pa = reference.features, reference.network, reference.training, reference.patches
            wide = " and ".join(f"a {METHOD_NAMES[m]} K = {k} normal" for m, k in f.wide_normals)
            last = "the last" if len(f.wide_normals) == 1 else f"the last {len(f.wide_normals)}"
            parts.append(
                f"Refine-Net: {n.preset} network, features {n.features}, connection {n.connection}, "
                + OUTPUT_CAPTIONS.get(n.output, "") +
                f"Kc = {reference.clustering.n_clusters}, X = {f.n_normals}"
                + (f" ({last}: {wide})" if wide else "")
                + (f", a K = 100 Jet normal where its residual is < {f.smooth_jet} x the noise" if f.smooth_jet else "")
                + f", r_f = {f.r_f}, {f.frame_mode} frames, {pa.mode} patches; {t.optimizer} lr {t.lr}"
                + (" (cosine decay)" if t.lr_schedule == "cosine" else "") + ", "
                f"batch {t.batch_size}, <= {t.max_epochs} epochs (patience {t.patience}), {t.loss} loss"
                + (f", at most {t.max_train_points_per_cloud} training points per cloud"
                   + (" (drawn anew every epoch)" if t.resample_points else "")
                   if t.max_train_points_per_cloud else "") + ".")
        budget = self.changes(REFERENCE)
        if compared and budget:
            main = asdict(self.full)
            parts.append("Every variant" + (", and Refine-Net as the reference row," if REFERENCE in compared else "")
                         + " under the variant budget: " + _settings(budget) + " (the main tables' Refine-Net: "
                         + _settings({k: config.get(main, k) for k in budget}) + ").")
        points = self.scored_subset(table.methods)
        if points is not None:
            parts.append(f"Every row scored on the same seeded {points} points of each test cloud.")
        changed = [f"{v}: " + (_settings(self.changes(v)) or "nothing (the settings above)")
                   for v in table.variants if v not in (FULL, REFERENCE)]
        if changed:
            parts.append("Variants of Refine-Net (what each changes): " + "; ".join(changed) + ".")
        return " ".join(parts)

    def protocol(self, table: Table) -> str:
        return table.protocol or self.full.evaluation.protocol

    def changes(self, variant: str) -> dict[str, Any]:
        """The settings in which a variant differs from reference (full under the variant budget, which every
        variant takes), by dotted key; reference's: those in which it differs from full (the budget)."""
        def flat(tree: Any, prefix: str = "") -> dict[str, Any]:
            if isinstance(tree, dict):
                return {k: v for key, value in tree.items() for k, v in flat(value, f"{prefix}{key}.").items()}
            return {prefix.rstrip("."): tree}
        base = self.full if variant == REFERENCE else self.params[REFERENCE]
        own, other = flat(asdict(base)), flat(asdict(self.params[variant]))
        return {k: other[k] for k in other if other[k] != own.get(k)}

    def _files(self, family: str, variant: str, split: str) -> str:
        """The folder of a per-variant step's files of one split (or the cluster model's, the networks')."""
        owner = self.owner(variant, family)
        return {"features": f"results/features/{owner}/{split}", "clustering": f"results/clusters/{owner}",
                "training": MODEL_DIR.format(variant=owner),
                "inference": f"results/normals/{REFINENET}/{owner}/{split}"}[family]

    def _normals_step(self, name: str, family: str, modules: tuple[str, ...], keys: tuple[str, ...],
                      methods: tuple[str, ...], splits: tuple[str, ...] = ("test",)) -> Step:
        """A step estimating normals of every cloud of `splits` with each of `methods`."""
        return Step(
            name=name, family=family, modules=(*modules, *_STAGE), keys=keys,
            deps=tuple(f"results/clouds/{s}" for s in splits),
            outs=tuple(f"results/normals/{m}/{s}" for m in methods for s in splits),
            targets=lambda: [self.normals_path(m, k) for m in methods for s in splits for k in self.keys(s)],
            split=splits[0] if len(splits) == 1 else None,
        )

    def _variant_steps(self, v: str) -> list[Step]:
        p, own, files = self.params[v], self.owners[v], self._files
        scored = v in self.scored
        splits = SPLITS if scored else ("train",)
        name = {family: family if v == FULL else f"{family}_{v}" for family in VARIANT_STEPS}
        keys = {family: keys for family, (keys, _) in VARIANT_STEPS.items()}
        made = {
            "features": lambda: Step(
                name=name["features"], family="features", modules=(*_FEATURES, *_DATA, *_STAGE), keys=keys["features"],
                deps=(*(f"results/clouds/{s}" for s in splits),
                      *(os.path.dirname(self.initial_path(v, f"{s}/x")) for s in splits)),
                outs=tuple(files("features", v, s) for s in splits), variant=v,
                targets=lambda: [FEATURES.format(variant=v, cloud=k) for s in splits for k in self.keys(s)],
                split=splits[0] if len(splits) == 1 else None,
            ),
            "clustering": lambda: Step(
                name=name["clustering"], family="clustering", modules=(*_FEATURES, "network.clustering", *_STAGE),
                keys=keys["clustering"], deps=(files("features", v, "train"),), outs=(files("clustering", v, ""),),
                targets=lambda: [CLUSTER_MODEL.format(variant=v)], variant=v,
            ),
            "training": lambda: Step(
                name=name["training"], family="training", modules=(*_NETWORK, *_STAGE), keys=keys["training"],
                deps=("results/clouds/train", files("features", v, "train"), files("clustering", v, "")),
                outs=(MODEL_DIR.format(variant=v),), plots=(HISTORY_DIR.format(variant=v),), variant=v,
                targets=lambda: [path.format(variant=v, cluster=c) for c in range(p.clustering.n_clusters)
                                 for path in (NETWORK, HISTORY)],
            ),
            "inference": lambda: Step(
                name=name["inference"], family="inference", modules=(*_NETWORK, "network.inference", *_DATA, *_STAGE),
                keys=keys["inference"],
                deps=("results/clouds/test", files("features", v, "test"), files("clustering", v, ""),
                      files("training", v, "")),
                outs=(files("inference", v, "test"),), variant=v,
                targets=lambda: [REFINED.format(variant=v, cloud=k) for k in self.keys("test")],
            ),
        }
        return [make() for family, make in made.items() if own[family] == v and (family != "inference" or scored)]

    def _table_step(self, name: str, table: Table) -> Step:
        blocks = _blocks(table.methods)
        variants = tuple(f"variants.{v}" for v in table.variants if v != FULL and _exists(self.raw, f"variants.{v}"))
        variants += ("inference.points",) if table.variants else ()
        variants += ("variant_budget",) if set(table.variants) - {FULL} else ()
        files = Table.files(name, table)
        normals = dict.fromkeys(map(self.normals_dir, table.methods))
        return Step(
            name=name, family="table", modules=(*_TABLE, *_STAGE),
            keys=("data.source", "data.path", "data.n_points", "evaluation.protocol", *blocks, *variants),
            deps=("results/clouds/test", *normals),
            outs=tuple(path for kind, path in files.items() if kind != "metrics"), metrics=(files["metrics"],),
            targets=lambda: list(files.values()),
        )

    def reported_files(self) -> list[str]:
        """The files the report page renders or links, as paths from the repository root."""
        tables, figures = self.reported()
        files = [os.path.join(REPORT_DIR, p) for entry in (*tables, *figures) for p in entry.links.values()]
        return list(dict.fromkeys([*files, COMPARISON_FILES["md"]]))

    def _real_steps(self) -> list[Step]:
        """The real-scan figure, where params.yaml `figures.scans` names a folder."""
        scans = self.full.figures.scans
        if not scans:
            return []
        return [Step(
            name="fig_real", family="fig",
            modules=_FIG,
            keys=("data.source", "data.path", "data.n_points", "figures.scans", "figures.scan_points", "baselines",
                  "mfps", "features", "network", "patches", "inference", "seed"), variant=REAL_VARIANT,
            deps=(scans, "results/clouds/train", self._files("clustering", REAL_VARIANT, ""),
                  self._files("training", REAL_VARIANT, "")),
            outs=tuple(FIGURE_REAL.values()), targets=lambda: list(FIGURE_REAL.values()),
        )]

    def _denoise_steps(self) -> list[Step]:
        """The denoising application's steps, where some test cloud has a known clean surface."""
        keys = self.denoise_keys()
        if not keys:
            return []
        normals = tuple(dict.fromkeys(map(self.normals_dir, DENOISE_METHODS)))
        records = os.path.dirname(DENOISED.format(cloud="test/x"))
        table = Table.files(DENOISE_TABLE)
        modules = ("evaluation.denoise", *_TABLE, *_STAGE)
        return [
            Step(
                name="denoise", family="denoise", modules=modules, keys=("denoise",),
                deps=("results/clouds/test", *normals), outs=(records,),
                targets=lambda: [DENOISED.format(cloud=k) for k in keys], split="test",
            ),
            Step(
                name=DENOISE_TABLE, family="denoise", modules=modules,
                keys=("data.source", "data.path", "data.n_points", "denoise"),
                deps=("results/clouds/test", records),
                outs=tuple(path for kind, path in table.items() if kind != "metrics"), metrics=(table["metrics"],),
                targets=lambda: list(table.values()),
            ),
            Step(
                name="fig_denoise", family="fig", modules=_FIG,
                keys=("data.source", "data.path", "data.n_points", "denoise"),
                deps=("results/clouds/test", records),
                outs=tuple(FIGURE_DENOISE.values()), targets=lambda: list(FIGURE_DENOISE.values()),
            ),
        ]

    def _steps(self) -> list[Step]:
        return [
            *(Step(
                name=f"clouds_{split}", family="clouds", modules=(*_DATA, *_STAGE),
                keys=("seed", "data", f"noise.{split}"), deps=(), outs=(f"results/clouds/{split}",),
                targets=lambda split=split: [CLOUD.format(cloud=k) for k in self.keys(split)], split=split,
            ) for split in SPLITS),
            *(self._normals_step(name, "baselines", ("estimators.baselines", "data.io", "data.shapes", "data.meshes",
                                                     *_GEOMETRY), ("baselines",), BASELINES, (split,))
              for name, split in (("baselines", "test"), ("baselines_train", "train"))
              if split == "test" or any(p.features.initial in BASELINES for p in self.params.values())),
            *(self._normals_step(name, "mfps", ("estimators.mfps", *_DATA, *_GEOMETRY), ("mfps", "seed"), methods,
                                 (split,))
              for name, split, methods in (("mfps", "test", MFPS_METHODS), ("mfps_train", "train", ("mfps",)))),
            *(step for v in self.params for step in self._variant_steps(v)),
            Step(
                name="release", family="release",
                modules=(*_NETWORK, "network.inference", "network.release", "geometry.scale", *_DATA, *_STAGE),
                keys=("seed", "data", "noise", "baselines", "mfps", "features", "clustering", "network", "patches",
                      "training", "inference", "evaluation", "denoise"),
                deps=("results/clouds/train", "results/clouds/test", self._files("features", FULL, "test"),
                      self._files("clustering", FULL, ""), self._files("training", FULL, "")),
                outs=(RELEASE,), targets=lambda: [RELEASE],
            ),
            *(self._table_step(name, table) for name, table in TABLES.items()),
            Step(
                name="paper_comparison", family="comparison", modules=("evaluation.paper", *_TABLE, *_STAGE),
                keys=("data.source", "data.path", "data.n_points", "evaluation.protocol"),
                deps=tuple(Table.files(name)["csv"] for name in TABLES), outs=tuple(COMPARISON_FILES.values()),
                targets=lambda: list(COMPARISON_FILES.values()),
            ),
            Step(
                name="table_time", family="time",
                modules=("pipeline.timing", "network.summary", "network.model", *_TABLE, *_STAGE),
                keys=("data.source", "data.path", "data.n_points", "mfps", "features", "clustering.n_clusters",
                      "network", "patches", "inference.device"),
                deps=("results/clouds/test", "results/normals/mfps/test", self._files("features", FULL, "test"),
                      self._files("inference", FULL, "test")),
                outs=tuple(path for kind, path in TIME_FILES.items() if kind != "metrics"),
                metrics=(TIME_FILES["metrics"],), targets=lambda: list(TIME_FILES.values()),
            ),
            Step(
                name="fig_normals", family="fig", modules=_FIG,
                keys=("data.source", "data.path", "data.n_points", "figures.variants", *_blocks(self.figure_methods()),
                      "inference.points", "variant_budget",
                      *(f"variants.{v}" for v in self.full.figures.variants if _exists(self.raw, f"variants.{v}"))),
                deps=("results/clouds/test", *dict.fromkeys(map(self.normals_dir, self.figure_methods()))),
                outs=tuple(FIGURE_NORMALS.values()), targets=lambda: list(FIGURE_NORMALS.values()),
            ),
            Step(
                name="fig_clusters", family="fig", modules=_FIG,
                keys=("data.source", "data.path", "data.n_points", "clustering",
                      *(f"variants.{v}" for v in CLUSTER_FIGURE_VARIANTS if _exists(self.raw, f"variants.{v}"))),
                deps=("results/clouds/test", self._files("features", FULL, "test"),
                      *dict.fromkeys(self._files("clustering", v, "") for v in CLUSTER_FIGURE_VARIANTS),
                      Table.files("table_clusters")["csv"]),
                outs=tuple(FIGURE_CLUSTERS.values()), targets=lambda: list(FIGURE_CLUSTERS.values()),
            ),
            Step(
                name="fig_loss", family="fig", modules=_FIG, keys=("data.source", "data.path", "data.n_points"),
                deps=("results/clouds/test", *dict.fromkeys(map(self.normals_dir, TABLES["table_loss"].methods))),
                outs=tuple(FIGURE_LOSS.values()), targets=lambda: list(FIGURE_LOSS.values()),
            ),
            Step(
                name="fig_training", family="fig", modules=_FIG,
                keys=("data.source", "data.path", "data.n_points"),
                deps=tuple(HISTORY_DIR.format(variant=v) for v in self.trained),
                outs=(FIGURE_TRAINING_DIR,),
                targets=lambda: [FIGURE_TRAINING.format(variant=v) for v in self.trained],
            ),
            *self._real_steps(),
            *self._denoise_steps(),
            Step(
                name="report", family="report", modules=("evaluation.report", *_TABLE, *_STAGE),
                keys=("seed", "data", "noise", "baselines", "mfps", "features", "clustering", "network", "patches",
                      "training", "inference", "evaluation", "denoise", "figures", "variants", "variant_budget"),
                deps=tuple(dict.fromkeys(FIGURE_TRAINING_DIR if p.startswith(f"{FIGURE_TRAINING_DIR}/") else p
                                         for p in self.reported_files())),
                outs=tuple(REPORT_FILES.values()),
                targets=lambda: list(REPORT_FILES.values()),
            ),
            Step(
                name="report_pdf", family="report", modules=("evaluation.report", *_TABLE, *_STAGE), keys=(),
                deps=(REPORT_FILES["tex"],), outs=(TABLES_PDF,), targets=lambda: [TABLES_PDF], needs="pdflatex",
            ),
            Step(
                name="table_architecture", family="architecture",
                modules=("network.summary", "network.model", *_TABLE, *_STAGE),
                keys=(*_ARCHITECTURE, *(f"variants.{v}" for v in ARCHITECTURE if v != FULL)),
                deps=(), outs=tuple(ARCHITECTURE_FILES.values()), targets=lambda: list(ARCHITECTURE_FILES.values()),
            ),
        ]


def figure_name(method: str) -> str:
    """A method's name in figures: its table name, or `Refine-Net <variant>` for a variant."""
    variant = variant_of(method)
    return METHOD_NAMES[method] if variant in (None, FULL) else f"{METHOD_NAMES[REFINENET]} {variant}"


def _settings(values: dict[str, Any]) -> str:
    """Dotted keys and their values as a caption lists them, None as params.yaml writes it."""
    return ", ".join(f"{k} = {'null' if v is None else v}" for k, v in values.items())


def _figure(files: dict[str, str]) -> dict[str, Any]:
    """A figure's PNG and its links (every format it is written in)."""
    return {"png": files["png"], "links": files}


def _blocks(methods: tuple[str, ...]) -> tuple[str, ...]:
    """The params blocks that configure the given methods (a Refine-Net variant's as Refine-Net's)."""
    return tuple(dict.fromkeys(b for m in methods for b in METHODS[REFINENET if variant_of(m) else m]))


def _typed(variant: str, resolved: dict[str, Any], source: str) -> Params:
    """A variant's typed params; full's are checked first, so a value only a variant's overrides make bad (e.g. a
    missing folder of initial normals) is reported under the variant's key."""
    try:
        return Params.from_resolved(resolved, source)
    except ParamsError as err:
        if variant == FULL:
            raise
        raise ParamsError(f"variants.{variant}.{err.key}", err.problem, source) from None


def _exists(tree: Any, dotted: str) -> bool:
    for part in dotted.split("."):
        if not isinstance(tree, dict) or part not in tree:
            return False
        tree = tree[part]
    return True


def tracked_keys(raw: dict[str, Any], step: Step) -> list[str]:
    """The params keys a step depends on: `profile`, its own keys, its variant's overrides of them (its own and the
    variant budget's), and every profile's overrides of all these."""
    overrides = ([f"{where}.{k}" for where in (f"variants.{step.variant}", "variant_budget") for k in step.keys]
                 if step.variant != FULL else [])
    keys = ["profile", *step.keys, *(k for k in overrides if _exists(raw, k))]
    for name, block in (raw.get("profiles") or {}).items():
        keys += [f"profiles.{name}.{k}" for k in (*step.keys, *overrides) if _exists(block, k)]
    return keys


def tracked_params(raw: dict[str, Any], step: Step) -> dict[str, Any]:
    """Values of `tracked_keys` as Snakemake rule params, read from the raw file exactly as DVC reads them, so a
    change of any of them (even one masked by the active profile) reruns the step in both tools."""
    return {k: config.get(raw, k) for k in tracked_keys(raw, step)}


def dvc_yaml(raw: dict[str, Any]) -> dict[str, Any]:
    """The dvc.yaml that mirrors the Snakemake rules: one stage per step, run through the bridge."""
    stages: dict[str, Any] = {}
    for step in Pipeline(raw).steps.values():
        stage: dict[str, Any] = {
            "cmd": f"python -m refinenet.pipeline.bridge run {step.name}",
            "deps": [*step.code, *step.deps],
            "params": tracked_keys(raw, step),
            "outs": [{o: {"cache": False}} if o.startswith(("reports/", RELEASE)) else o for o in step.outs],
        }
        if step.metrics:
            stage["metrics"] = [{m: {"cache": False}} for m in step.metrics]
        if step.plots:
            stage["plots"] = [{p: {"x": "epoch", "y": "val_rmse_deg"}} for p in step.plots]
        stages[step.name] = stage
    return {"stages": stages}


def render_dvc_yaml(raw: dict[str, Any]) -> str:
    header = ("# Generated by `python -m refinenet.pipeline.workflow` from src/refinenet/pipeline/workflow.py; "
              "do not edit by hand.\n")
    return header + yaml.safe_dump(dvc_yaml(raw), sort_keys=False, width=120)


def dvc_yaml_is_current(raw: dict[str, Any]) -> bool:
    """Whether dvc.yaml is the one these params generate: an edit that adds or removes a params key (e.g.
    `variant_budget: {}`) changes the keys its stages track, and DVC cannot record a stage whose keys are gone."""
    return DVC_FILE.exists() and DVC_FILE.read_text() == render_dvc_yaml(raw)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Write dvc.yaml from the pipeline's step declarations.")
    parser.add_argument("--params", default="params.yaml")
    parser.add_argument("--check", action="store_true", help="exit 1 if dvc.yaml is out of date")
    args = parser.parse_args(argv)
    raw = config.read_raw(args.params)
    if args.check:
        if not dvc_yaml_is_current(raw):
            print(f"dvc.yaml is out of date: {REGENERATE}", file=sys.stderr)
            return 1
        return 0
    DVC_FILE.write_text(render_dvc_yaml(raw))
    return 0


if __name__ == "__main__":
    sys.exit(main())

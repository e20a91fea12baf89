"""The pipeline's steps, declared once for both Snakemake and DVC.

A step has one name everywhere: its DVC stage and its Snakemake rule carry it, and its family (the step's name
without an instance suffix such as `_train` or `_synthetic`) names its rule file `workflow/rules/FAMILY.smk`
and its stage script `stages/FAMILY.py`. Each `Step` lists the params keys it reads, its code, and the files it
reads and writes. The Snakefile takes rule params and code inputs from here; `dvc.yaml` is generated from here
(`refinenet.pipeline.dvc`), and a test checks the two agree, so changing a key reruns exactly the same steps in
both tools.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from refinenet import config
from refinenet.data.clouds import SPLITS
from refinenet.pipeline import layout
from refinenet.pipeline.captions import DATA_KEYS
from refinenet.pipeline.catalogue import (
    ARCHITECTURE,
    CLUSTER_FIGURE_VARIANTS,
    COMPARED_TABLES,
    DENOISE_METHODS,
    DENOISE_TABLE,
    REAL_VARIANT,
    SCAN_TABLE,
    TABLES,
    Table,
)
from refinenet.pipeline.methods import BASELINES, FULL, MFPS_METHODS, blocks
from refinenet.pipeline.page import reported_files
from refinenet.pipeline.variants import ARCHITECTURE_KEYS, VARIANT_STEPS, written

if TYPE_CHECKING:
    from refinenet.pipeline.workflow import Pipeline


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


def tracked_keys(raw: dict[str, Any], step: Step) -> list[str]:
    """The params keys a step depends on: `profile`, its own keys, its variant's overrides of them (its own and the
    variant budget's), and every profile's overrides of all these."""
    overrides = ([f"{where}.{k}" for where in (f"variants.{step.variant}", "variant_budget") for k in step.keys]
                 if step.variant != FULL else [])
    keys = ["profile", *step.keys, *(k for k in overrides if written(raw, k))]
    for name, block in (raw.get("profiles") or {}).items():
        keys += [f"profiles.{name}.{k}" for k in (*step.keys, *overrides) if written(block, k)]
    return keys


def tracked_params(raw: dict[str, Any], step: Step) -> dict[str, Any]:
    """Values of `tracked_keys` as Snakemake rule params, read from the raw file exactly as DVC reads them, so a
    change of any of them (even one masked by the active profile) reruns the step in both tools."""
    return {k: config.get(raw, k) for k in tracked_keys(raw, step)}


def gpus(device: str) -> int:
    """The `gpu` resource of a rule whose params name `device`: one GPU for cuda and auto, none for cpu. A cluster
    executor turns it into a GPU request (SLURM: --gpus=1); a local run caps concurrent GPU jobs with
    `--resources gpu=N`; rules without it never wait for a GPU."""
    return 0 if device == "cpu" else 1


#: Library modules the stage scripts import, in groups (a test checks every script against its step's list).
_STAGE = ("config", "errors", "atomic", "interrupts", "threads", "allocator", "profiling", "pipeline.stage")
_DATA = ("data.clouds", "data.shapes", "data.meshes", "data.noise", "data.io")
_GEOMETRY = ("geometry.neighbors", "geometry.grid_knn", "geometry.ball")
_FEATURES = ("features.cache", "features.filtering", "features.heightmaps", "geometry.frames", *_GEOMETRY, "data.io",
             "data.noise", "estimators.baselines", "estimators.smooth_jet", "data.shapes", "data.meshes")
_NETWORK = (*_FEATURES, "network.clustering", "network.dataset", "network.model", "network.fused", "network.pooling",
            "network.devices", "network.training", "features.patches", "evaluation.metrics")
#: The pipeline's declarations, which a script reading the pipeline (`workflow.Pipeline`) imports together.
_PIPELINE = ("pipeline.methods", "pipeline.layout", "pipeline.catalogue", "pipeline.variants", "pipeline.captions",
             "pipeline.page", "pipeline.steps", "pipeline.workflow", "data.scans")
_TABLE = ("evaluation.table", "evaluation.metrics", "evaluation.plots", *_PIPELINE, "estimators.baselines",
          "estimators.mfps", *_DATA, *_GEOMETRY)
#: The chain of `refinenet normals`, which the scan table and figure run.
_CHAIN = ("cli.estimate", "estimators.strata", "network.inference", "network.release", "network.devices",
          "geometry.scale", "geometry.tiles", *_NETWORK)
#: The figure script's (one for the fig steps).
_FIG = ("evaluation.figures", "evaluation.render", "evaluation.denoise", "geometry.orientation", *_CHAIN, *_TABLE,
        *_STAGE)


def declare(pipe: Pipeline) -> list[Step]:
    """Every step of the pipeline, upstream first (the order of dvc.yaml's stages)."""
    return [*_clouds_steps(pipe), *_estimator_steps(pipe), *(s for v in pipe.params for s in _variant_steps(pipe, v)),
            _release_step(pipe), *(_table_step(pipe, name, table) for name, table in TABLES.items()),
            *_summary_steps(pipe), *_figure_steps(pipe), *_scan_steps(pipe), *_denoise_steps(pipe),
            *_report_steps(pipe)]


def _clouds_steps(pipe: Pipeline) -> list[Step]:
    return [Step(
        name=f"clouds_{split}", family="clouds", modules=(*_DATA, *_STAGE),
        keys=("seed", "data", f"noise.{split}"), deps=(), outs=(f"results/clouds/{split}",),
        targets=lambda split=split: [layout.CLOUD.format(cloud=k) for k in pipe.keys(split)], split=split,
    ) for split in SPLITS]


def _estimator_steps(pipe: Pipeline) -> list[Step]:
    """The baselines' and MFPS's normals of the test clouds and of the training clouds (the baselines' only where some
    variant's features start from them)."""
    baselines = ("estimators.baselines", "data.io", "data.shapes", "data.meshes", *_GEOMETRY)
    return [
        *(_normals_step(pipe, name, "baselines", baselines, ("baselines",), BASELINES, split)
          for name, split in (("baselines", "test"), ("baselines_train", "train"))
          if split == "test" or any(p.features.initial in BASELINES for p in pipe.params.values())),
        *(_normals_step(pipe, name, "mfps", ("estimators.mfps", *_DATA, *_GEOMETRY), ("mfps", "seed"), methods, split)
          for name, split, methods in (("mfps", "test", MFPS_METHODS), ("mfps_train", "train", ("mfps",)))),
    ]


def _normals_step(pipe: Pipeline, name: str, family: str, modules: tuple[str, ...], keys: tuple[str, ...],
                  methods: tuple[str, ...], split: str) -> Step:
    """A step estimating normals of every cloud of `split` with each of `methods`."""
    return Step(
        name=name, family=family, modules=(*modules, *_STAGE), keys=keys, deps=(f"results/clouds/{split}",),
        outs=tuple(f"results/normals/{m}/{split}" for m in methods),
        targets=lambda: [pipe.normals_path(m, k) for m in methods for k in pipe.keys(split)], split=split,
    )


def _variant_steps(pipe: Pipeline, v: str) -> list[Step]:
    """The per-variant steps variant `v` owns; inference only for a variant a table or the normals figure scores."""
    p, files = pipe.params[v], pipe.variant_dir
    scored = v in pipe.scored
    splits = SPLITS if scored else ("train",)
    name = {family: family if v == FULL else f"{family}_{v}" for family in VARIANT_STEPS}
    keys = {family: keys for family, (keys, _) in VARIANT_STEPS.items()}
    made = {
        "features": lambda: Step(
            name=name["features"], family="features", modules=(*_FEATURES, *_DATA, *_STAGE), keys=keys["features"],
            deps=(*(f"results/clouds/{s}" for s in splits),
                  *(os.path.dirname(pipe.initial_path(v, f"{s}/x")) for s in splits)),
            outs=tuple(files("features", v, s) for s in splits), variant=v,
            targets=lambda: [layout.FEATURES.format(variant=v, cloud=k) for s in splits for k in pipe.keys(s)],
            split=splits[0] if len(splits) == 1 else None,
        ),
        "clustering": lambda: Step(
            name=name["clustering"], family="clustering", modules=(*_FEATURES, "network.clustering", *_STAGE),
            keys=keys["clustering"], deps=(files("features", v, "train"),), outs=(files("clustering", v, ""),),
            targets=lambda: [layout.CLUSTER_MODEL.format(variant=v)], variant=v,
        ),
        "training": lambda: Step(
            name=name["training"], family="training", modules=(*_NETWORK, *_STAGE), keys=keys["training"],
            deps=("results/clouds/train", files("features", v, "train"), files("clustering", v, "")),
            outs=(layout.MODEL_DIR.format(variant=v),), plots=(layout.HISTORY_DIR.format(variant=v),), variant=v,
            targets=lambda: [path.format(variant=v, cluster=c) for c in range(p.clustering.n_clusters)
                             for path in (layout.NETWORK, layout.HISTORY)],
        ),
        "inference": lambda: Step(
            name=name["inference"], family="inference", modules=(*_NETWORK, "network.inference", *_DATA, *_STAGE),
            keys=keys["inference"],
            deps=("results/clouds/test", files("features", v, "test"), files("clustering", v, ""),
                  files("training", v, "")),
            outs=(files("inference", v, "test"),), variant=v,
            targets=lambda: [layout.REFINED.format(variant=v, cloud=k) for k in pipe.keys("test")],
        ),
    }
    own = pipe.owners[v]
    return [make() for family, make in made.items() if own[family] == v and (family != "inference" or scored)]


def _release_step(pipe: Pipeline) -> Step:
    return Step(
        name="release", family="release",
        modules=(*_NETWORK, "network.inference", "network.release", "geometry.scale", *_DATA, *_STAGE),
        keys=("seed", "data", "noise", "baselines", "mfps", "features", "clustering", "network", "patches",
              "training", "inference", "evaluation", "denoise"),
        deps=("results/clouds/train", "results/clouds/test", pipe.variant_dir("features", FULL, "test"),
              pipe.variant_dir("clustering", FULL, ""), pipe.variant_dir("training", FULL, "")),
        outs=(layout.RELEASE,), targets=lambda: [layout.RELEASE],
    )


def _variant_keys(pipe: Pipeline, variants: Iterable[str]) -> tuple[str, ...]:
    """The `variants.<v>` blocks params.yaml writes for the given variants (full has none)."""
    return tuple(f"variants.{v}" for v in variants if v != FULL and written(pipe.raw, f"variants.{v}"))


def _table_files(name: str, files: dict[str, str], **step: Any) -> Step:
    """A step writing a table's files: the metrics record as DVC metrics, the others as outputs."""
    return Step(name=name, outs=tuple(path for kind, path in files.items() if kind != "metrics"),
                metrics=(files["metrics"],), targets=lambda: list(files.values()), **step)


def _table_step(pipe: Pipeline, name: str, table: Table) -> Step:
    variants = _variant_keys(pipe, table.variants)
    variants += ("inference.points",) if table.variants else ()
    variants += ("variant_budget",) if set(table.variants) - {FULL} else ()
    return _table_files(
        name, Table.files(name, table), family="table", modules=(*_TABLE, *_STAGE),
        keys=(*DATA_KEYS, "evaluation.protocol", *blocks(table.methods), *variants),
        deps=("results/clouds/test", *dict.fromkeys(map(pipe.normals_dir, table.methods))),
    )


def _summary_steps(pipe: Pipeline) -> list[Step]:
    """The comparison with the paper's numbers and the time table."""
    return [
        Step(
            name="paper_comparison", family="comparison", modules=("evaluation.paper", *_TABLE, *_STAGE),
            keys=(*DATA_KEYS, "evaluation.protocol"),
            deps=tuple(Table.files(name)["csv"] for name in COMPARED_TABLES),
            outs=tuple(layout.COMPARISON_FILES.values()),
            targets=lambda: list(layout.COMPARISON_FILES.values()),
        ),
        _table_files(
            "table_time", layout.TIME_FILES, family="time",
            modules=("pipeline.timing", "network.summary", "network.model", "network.pooling", *_TABLE, *_STAGE),
            keys=(*DATA_KEYS, "mfps", "features", "clustering.n_clusters", "network", "patches", "inference.device"),
            deps=("results/clouds/test", "results/normals/mfps/test", pipe.variant_dir("features", FULL, "test"),
                  pipe.variant_dir("inference", FULL, "test")),
        ),
    ]


def _figure(name: str, files: dict[str, str], keys: tuple[str, ...], deps: tuple[str, ...], **step: Any) -> Step:
    """A figure step: the figure script, the data line its footer names, and every format the figure is written in."""
    return Step(name=name, family="fig", modules=_FIG, keys=(*DATA_KEYS, *keys), deps=deps,
                outs=tuple(files.values()), targets=lambda: list(files.values()), **step)


def _figure_steps(pipe: Pipeline) -> list[Step]:
    """The normals, clusters, loss and training figures."""
    figure_methods = pipe.figure_methods()
    return [
        _figure("fig_normals", layout.FIGURE_NORMALS,
                ("figures.variants", *blocks(figure_methods), "inference.points", "variant_budget",
                 *_variant_keys(pipe, pipe.full.figures.variants)),
                ("results/clouds/test", *dict.fromkeys(map(pipe.normals_dir, figure_methods)))),
        _figure("fig_clusters", layout.FIGURE_CLUSTERS, ("clustering", *_variant_keys(pipe, CLUSTER_FIGURE_VARIANTS)),
                ("results/clouds/test", pipe.variant_dir("features", FULL, "test"),
                 *dict.fromkeys(pipe.variant_dir("clustering", v, "") for v in CLUSTER_FIGURE_VARIANTS),
                 Table.files("table_clusters")["csv"])),
        _figure("fig_loss", layout.FIGURE_LOSS, (),
                ("results/clouds/test", *dict.fromkeys(map(pipe.normals_dir, TABLES["table_loss"].methods)))),
        Step(
            name="fig_training", family="fig", modules=_FIG, keys=DATA_KEYS,
            deps=tuple(layout.HISTORY_DIR.format(variant=v) for v in pipe.trained), outs=(layout.FIGURE_TRAINING_DIR,),
            targets=lambda: [layout.FIGURE_TRAINING.format(variant=v) for v in pipe.trained],
        ),
    ]


def _scan_steps(pipe: Pipeline) -> list[Step]:
    """The simulated scans, their table and the scan figure (on a user's folder of scans where `figures.scans`
    names one). The table and figure run the chain of `refinenet normals` (cli.estimate) with variant x8's
    networks; the table also with the release's."""
    x8 = (pipe.variant_dir("clustering", REAL_VARIANT, ""), pipe.variant_dir("training", REAL_VARIANT, ""))
    estimated = ("baselines", "mfps", "features", "network", "patches", "inference", "seed")
    return [
        Step(name="simulate_scans", family="simulate",
             modules=("data.scans", "data.shapes", "data.meshes", "data.noise", "data.io", *_STAGE),
             keys=("seed", "scanner"), deps=(), outs=(layout.SCANS_DIR,),
             targets=lambda: [layout.SCAN.format(shape=s) for s in pipe.scanner.shapes]),
        _table_files(SCAN_TABLE, Table.files(SCAN_TABLE), family="scans", modules=(*_CHAIN, *_TABLE, *_STAGE),
                     keys=(*DATA_KEYS, "scanner", *estimated),
                     deps=(layout.SCANS_DIR, layout.RELEASE, "results/clouds/train", *x8), variant=REAL_VARIANT),
        _figure("fig_real", layout.FIGURE_REAL, ("figures.scans", "figures.scan_points", *estimated),
                (pipe.scans_folder(), "results/clouds/train", *x8), variant=REAL_VARIANT),
    ]


def _denoise_steps(pipe: Pipeline) -> list[Step]:
    """The denoising application's steps, where some test cloud has a known clean surface."""
    keys = pipe.denoise_keys()
    if not keys:
        return []
    normals = tuple(dict.fromkeys(map(pipe.normals_dir, DENOISE_METHODS)))
    records = os.path.dirname(layout.DENOISED.format(cloud="test/x"))
    modules = ("evaluation.denoise", *_TABLE, *_STAGE)
    return [
        Step(
            name="denoise", family="denoise", modules=modules, keys=("denoise",),
            deps=("results/clouds/test", *normals), outs=(records,),
            targets=lambda: [layout.DENOISED.format(cloud=k) for k in keys], split="test",
        ),
        _table_files(DENOISE_TABLE, Table.files(DENOISE_TABLE), family="denoise", modules=modules,
                     keys=(*DATA_KEYS, "denoise"), deps=("results/clouds/test", records)),
        _figure("fig_denoise", layout.FIGURE_DENOISE, ("denoise",), ("results/clouds/test", records)),
    ]


def _report_steps(pipe: Pipeline) -> list[Step]:
    """The report page and its PDF, then the architecture table (which needs no data)."""
    modules = ("evaluation.report", *_TABLE, *_STAGE)
    return [
        Step(
            name="report", family="report", modules=modules,
            keys=("seed", "data", "noise", "baselines", "mfps", "features", "clustering", "network", "patches",
                  "training", "inference", "evaluation", "denoise", "figures", "scanner", "variants", "variant_budget"),
            deps=tuple(dict.fromkeys(layout.FIGURE_TRAINING_DIR if p.startswith(f"{layout.FIGURE_TRAINING_DIR}/") else p
                                     for p in reported_files(pipe))),
            outs=tuple(layout.REPORT_FILES.values()), targets=lambda: list(layout.REPORT_FILES.values()),
        ),
        Step(
            name="report_pdf", family="report", modules=modules, keys=(),
            deps=(layout.REPORT_FILES["tex"],), outs=(layout.TABLES_PDF,), targets=lambda: [layout.TABLES_PDF],
            needs="pdflatex",
        ),
        Step(
            name="table_architecture", family="architecture",
            modules=("network.summary", "network.model", "network.pooling", *_TABLE, *_STAGE),
            keys=(*ARCHITECTURE_KEYS, *(f"variants.{v}" for v in ARCHITECTURE if v != FULL)),
            deps=(), outs=tuple(layout.ARCHITECTURE_FILES.values()),
            targets=lambda: list(layout.ARCHITECTURE_FILES.values()),
        ),
    ]

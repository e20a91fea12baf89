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
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from refinenet import config
from refinenet.config import Params
from refinenet.data.clouds import SPLITS, CloudSpec, list_clouds
from refinenet.estimators.baselines import METHODS as BASELINES
from refinenet.estimators.mfps import METHODS as MFPS_METHODS

DVC_FILE = Path("dvc.yaml")
REFINENET = "refinenet"

#: File layout, as Snakemake patterns: `{cloud}` is a cloud's key `<split>/<category>/<name>`.
CLOUD = "results/clouds/{cloud}.npz"
FEATURES = "results/features/{cloud}.npz"
NORMALS = "results/normals/{method}/{cloud}.npy"
#: Refine-Net's output is the PCPNet text format, the form users compare with other methods.
REFINED = f"results/normals/{REFINENET}/{{cloud}}.normals"
CLUSTER_MODEL = "results/clusters/model.npz"
MODEL_DIR = f"results/models/{REFINENET}"
NETWORK = f"{MODEL_DIR}/cluster_{{cluster}}"
HISTORY_DIR = f"results/history/{REFINENET}"
HISTORY = f"{HISTORY_DIR}/cluster_{{cluster}}.csv"
#: Resumable training state, outside every step's outputs so that neither tool clears it before a rerun.
CHECKPOINT_DIR = f"results/checkpoints/{REFINENET}"
#: The shipped release (`network.release`): committed with the package, so it is not DVC-cached.
RELEASE = "src/refinenet/shipped"
TABLE_FILES = {"csv": "reports/{table}.csv", "tex": "reports/{table}.tex", "per_cloud": "reports/per_cloud/{table}.csv"}
TABLE_METRICS = "reports/metrics/{table}.json"
METRICS = "reports/metrics.json"


def clouds(params: Params, split: str | None = None) -> list[CloudSpec]:
    """The run's clouds (optionally of one split)."""
    return [c for c in list_clouds(params.data, params.noise) if split in (None, c.split)]


def check_keys(params: Params) -> list[str]:
    """One test cloud per category (the first): where the release measures what half precision changes."""
    first: dict[str, str] = {}
    for c in clouds(params, "test"):
        first.setdefault(c.category, c.key)
    return list(first.values())


def gpus(device: str) -> int:
    """The `gpu` resource of a rule whose params name `device`: one GPU for cuda and auto, none for cpu. A cluster
    executor turns it into a GPU request (SLURM: --gpus=1); a local run caps concurrent GPU jobs with
    `--resources gpu=N`; rules without it never wait for a GPU."""
    return 0 if device == "cpu" else 1


def normals_path(method: str, cloud: str) -> str:
    """Estimated normals of the cloud with key `cloud`."""
    return REFINED.format(cloud=cloud) if method == REFINENET else NORMALS.format(method=method, cloud=cloud)


@dataclass(frozen=True)
class Table:
    """A results table of the paper: which methods are its rows and which metrics its columns."""

    methods: tuple[str, ...]
    metrics: tuple[str, ...]
    title: str

    @staticmethod
    def files(name: str) -> dict[str, str]:
        """The table's outputs by kind: csv, tex, per_cloud and its metrics record."""
        return {**{kind: path.format(table=name) for kind, path in TABLE_FILES.items()},
                "metrics": TABLE_METRICS.format(table=name)}


#: Normal estimators and the params blocks that configure each (their values are named in table captions).
METHODS = {**{m: ("baselines",) for m in BASELINES}, **{m: ("mfps",) for m in MFPS_METHODS},
           REFINENET: ("mfps", "features", "clustering", "network", "patches", "training")}
_SYNTHETIC = (*BASELINES, *MFPS_METHODS, REFINENET)
TABLES = {
    "table_baselines": Table(BASELINES, ("mean", "rmse"), "Baselines: unoriented angular error (degrees)"),
    "table_synthetic": Table(_SYNTHETIC, ("mean", "rmse"), "Synthetic benchmark: unoriented angular error (degrees)"),
    "table_synthetic_pgp": Table(_SYNTHETIC, ("pgp5", "pgp10"),
                                 "Synthetic benchmark: proportion of good points (error below 5 and 10 degrees)"),
}


@dataclass(frozen=True)
class Step:
    """One pipeline step: a DVC stage and the Snakemake rule of the same name that makes its files."""

    name: str
    family: str
    """The rule file and stage script shared by the instances of a step (e.g. clouds_train and clouds_test)."""
    modules: tuple[str, ...]
    """Library modules (dotted, below `refinenet`) that the stage script imports."""
    keys: tuple[str, ...]
    """params.yaml keys the step reads; a change of any of them reruns it in both tools."""
    deps: tuple[str, ...]
    outs: tuple[str, ...]
    targets: Callable[[Params], list[str]]
    """Every file the step makes for the given params."""
    metrics: tuple[str, ...] = ()
    plots: tuple[str, ...] = ()

    @property
    def code(self) -> list[str]:
        """Files whose change must rerun the step: the Snakefile and shared rules, its rule file and stage script,
        and every library module it imports."""
        return ["workflow/Snakefile", "workflow/rules/common.smk", f"workflow/rules/{self.family}.smk",
                "stages/__init__.py", f"stages/{self.family}.py",
                *(f"src/refinenet/{m.replace('.', '/')}.py" for m in dict.fromkeys(self.modules))]


#: Library modules the stage scripts import, in groups (a test checks every script against its step's list).
_STAGE = ("config", "errors", "atomic", "threads", "pipeline.stage")
_DATA = ("data.clouds", "data.shapes", "data.meshes", "data.noise", "data.io")
_GEOMETRY = ("geometry.neighbors", "geometry.grid_knn", "geometry.ball")
_FEATURES = ("features.cache", "features.filtering", "features.heightmaps", "geometry.frames", *_GEOMETRY, "data.io",
             "data.noise")
_NETWORK = (*_FEATURES, "network.clustering", "network.dataset", "network.model", "network.devices", "network.training",
            "features.patches", "evaluation.metrics")
_TABLE = ("evaluation.table", "evaluation.metrics", "data.io", "data.shapes", "data.meshes")

#: The keys that fix the network (`network.model.architecture`): X and m come from the features block.
_ARCHITECTURE = ("features.sigma_s", "features.sigma_r", "features.include_initial", "features.hmp_size", "network",
                 "patches")


def _normals_step(name: str, family: str, modules: tuple[str, ...], keys: tuple[str, ...],
                  methods: tuple[str, ...], splits: tuple[str, ...] = ("test",)) -> Step:
    """A step estimating normals of every cloud of `splits` with each of `methods`."""
    return Step(
        name=name, family=family, modules=(*modules, *_STAGE), keys=keys,
        deps=tuple(f"results/clouds/{s}" for s in splits),
        outs=tuple(f"results/normals/{m}/{s}" for m in methods for s in splits),
        targets=lambda p: [normals_path(m, c.key) for m in methods for s in splits for c in clouds(p, s)],
    )


def _table_step(name: str, table: Table) -> Step:
    blocks = tuple(dict.fromkeys(b for m in table.methods for b in METHODS[m]))
    files = Table.files(name)
    return Step(
        name=name, family="table", modules=(*_TABLE, "pipeline.workflow", "estimators.baselines", "estimators.mfps",
                                           *_DATA, *_GEOMETRY, *_STAGE),
        keys=("data.source", "data.path", "data.n_points", "evaluation.protocol", *blocks),
        deps=("results/clouds/test", *(f"results/normals/{m}/test" for m in table.methods)),
        outs=(files["csv"], files["tex"], files["per_cloud"]), metrics=(files["metrics"],),
        targets=lambda p: list(files.values()),
    )


STEPS: dict[str, Step] = {s.name: s for s in (
    *(Step(
        name=f"clouds_{split}", family="clouds", modules=(*_DATA, *_STAGE), keys=("seed", "data", f"noise.{split}"),
        deps=(), outs=(f"results/clouds/{split}",),
        targets=lambda p, split=split: [CLOUD.format(cloud=c.key) for c in clouds(p, split)],
    ) for split in SPLITS),
    _normals_step("baselines", "baselines", ("estimators.baselines", "data.io", "data.shapes", "data.meshes",
                                             *_GEOMETRY), ("baselines",), BASELINES),
    _normals_step("mfps", "mfps", ("estimators.mfps", *_DATA, *_GEOMETRY), ("mfps", "seed"), ("mfps",), SPLITS),
    _normals_step("simple_mfps", "mfps", ("estimators.mfps", *_DATA, *_GEOMETRY), ("mfps", "seed"),
                  ("simple_mfps",)),
    Step(
        name="features", family="features", modules=(*_FEATURES, *_STAGE), keys=("features",),
        deps=(*(f"results/clouds/{s}" for s in SPLITS), *(f"results/normals/mfps/{s}" for s in SPLITS)),
        outs=tuple(f"results/features/{s}" for s in SPLITS),
        targets=lambda p: [FEATURES.format(cloud=c.key) for c in clouds(p)],
    ),
    Step(
        name="clustering", family="clustering", modules=(*_FEATURES, "network.clustering", *_STAGE),
        keys=("clustering", "seed"), deps=("results/features/train",), outs=("results/clusters",),
        targets=lambda p: [CLUSTER_MODEL],
    ),
    Step(
        name="training", family="training", modules=(*_NETWORK, *_STAGE),
        keys=(*_ARCHITECTURE, "training", "seed"),
        deps=("results/clouds/train", "results/features/train", "results/clusters"), outs=(MODEL_DIR,),
        plots=(HISTORY_DIR,),
        targets=lambda p: [path.format(cluster=c) for c in range(p.clustering.n_clusters)
                           for path in (NETWORK, HISTORY)],
    ),
    Step(
        name="inference", family="inference", modules=(*_NETWORK, "network.inference", *_DATA, *_STAGE),
        keys=(*_ARCHITECTURE, "inference", "seed"),
        deps=("results/clouds/test", "results/features/test", "results/clusters", MODEL_DIR),
        outs=(f"results/normals/{REFINENET}/test",),
        targets=lambda p: [normals_path(REFINENET, c.key) for c in clouds(p, "test")],
    ),
    Step(
        name="release", family="release",
        modules=(*_NETWORK, "network.inference", "network.release", "geometry.scale", *_DATA, *_STAGE),
        keys=("seed", "data", "noise", "baselines", "mfps", "features", "clustering", "network", "patches", "training",
              "inference", "evaluation"),
        deps=("results/clouds/train", "results/clouds/test", "results/features/test", "results/clusters", MODEL_DIR),
        outs=(RELEASE,), targets=lambda p: [RELEASE],
    ),
    *(_table_step(name, table) for name, table in TABLES.items()),
    Step(
        name="metrics", family="metrics", modules=(*_TABLE, *_STAGE),
        keys=(), deps=tuple(Table.files(n)["metrics"] for n in TABLES), outs=(), metrics=(METRICS,),
        targets=lambda p: [METRICS],
    ),
)}


def caption(title: str, params: Params, methods: tuple[str, ...]) -> str:
    """A table caption naming the profile, the data and the settings of every method in the table."""
    d, b, m = params.data, params.baselines, params.mfps
    parts = [
        f"{title}, {params.evaluation.protocol} protocol.",
        f"Profile {params.profile}; data: {d.source}" + (f" ({d.path})" if d.path else "")
        + f", {d.n_points} points per cloud.",
    ]
    if set(BASELINES) & set(methods):
        parts.append(f"PCA/Jet K = {b.pca_k}/{b.jet_k} ({b.big_noise_k} for BigNoise), jet degree {b.jet_degree}.")
    if set(MFPS_METHODS) & set(methods):
        parts.append(f"MFPS K = {{{', '.join(map(str, m.scales))}}}, R = {m.trials}, "
                     f"theta_t = {m.theta_t} deg, |A| <= {m.a_max}, eta = {m.eta}.")
    if REFINENET in methods:
        f, n, t, pa = params.features, params.network, params.training, params.patches
        parts.append(
            f"Refine-Net: {n.preset} network, features {n.features}, connection {n.connection}, "
            f"Kc = {params.clustering.n_clusters}, X = {f.n_normals}"
            f", r_f = {f.r_f}, {f.frame_mode} frames, {pa.mode} patches; {t.optimizer} lr {t.lr}, "
            f"batch {t.batch_size}, <= {t.max_epochs} epochs (patience {t.patience}), {t.loss} loss"
            + (f", at most {t.max_train_points_per_cloud} training points per cloud"
               if t.max_train_points_per_cloud else "") + ".")
    return " ".join(parts)


def _exists(tree: Any, dotted: str) -> bool:
    for part in dotted.split("."):
        if not isinstance(tree, dict) or part not in tree:
            return False
        tree = tree[part]
    return True


def tracked_keys(raw: dict[str, Any], step: Step) -> list[str]:
    """The params keys a step depends on: `profile`, its own keys, and every profile's overrides of them."""
    keys = ["profile", *step.keys]
    for name, block in (raw.get("profiles") or {}).items():
        keys += [f"profiles.{name}.{k}" for k in step.keys if _exists(block, k)]
    return keys


def tracked_params(raw: dict[str, Any], step: Step) -> dict[str, Any]:
    """Values of `tracked_keys` as Snakemake rule params, read from the raw file exactly as DVC reads them, so a
    change of any of them (even one masked by the active profile) reruns the step in both tools."""
    return {k: config.get(raw, k) for k in tracked_keys(raw, step)}


def dvc_yaml(raw: dict[str, Any]) -> dict[str, Any]:
    """The dvc.yaml that mirrors the Snakemake rules: one stage per step, run through the bridge."""
    stages: dict[str, Any] = {}
    for step in STEPS.values():
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Write dvc.yaml from the pipeline's step declarations.")
    parser.add_argument("--params", default="params.yaml")
    parser.add_argument("--check", action="store_true", help="exit 1 if dvc.yaml is out of date")
    args = parser.parse_args(argv)
    text = render_dvc_yaml(config.read_raw(args.params))
    if args.check:
        current = DVC_FILE.read_text() if DVC_FILE.exists() else ""
        if current != text:
            print("dvc.yaml is out of date: run `python -m refinenet.pipeline.workflow`", file=sys.stderr)
            return 1
        return 0
    DVC_FILE.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())

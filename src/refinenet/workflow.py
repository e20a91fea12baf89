"""The pipeline's steps, declared once for both Snakemake and DVC.

Each `Step` names the Snakemake rule that does the work, the params keys it reads, the code it runs and
the files it reads and writes. The Snakefile takes rule params and code inputs from here; `dvc.yaml` is
generated from here (`python -m refinenet.workflow`), and a test checks the two agree, so changing a key
reruns exactly the same steps in both tools.
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
from refinenet.sources import CloudSpec, list_clouds

BASELINES = ("pca", "jet")
DVC_FILE = Path("dvc.yaml")


def clouds(params: dict[str, Any], split: str | None = None) -> list[CloudSpec]:
    """The run's clouds (optionally of one split), from the resolved params."""
    return [c for c in list_clouds(params["data"], params["noise"]) if split in (None, c.split)]


def cloud_path(spec: CloudSpec) -> str:
    return f"results/clouds/{spec.key}.npz"


def normals_path(method: str, spec: CloudSpec) -> str:
    """Estimated normals: binary for the intermediate estimators, the PCPNet text format for Refine-Net's output."""
    return f"results/normals/{method}/{spec.key}.{'normals' if method == REFINENET else 'npy'}"


def features_path(spec: CloudSpec) -> str:
    return f"results/features/{spec.key}.npz"


CLUSTER_MODEL = "results/clusters/model.npz"
MODEL_DIR = "results/models/refinenet"
CHECKPOINT_DIR = "results/checkpoints/refinenet"
REFINENET = "refinenet"


def trained_marker(cluster: int) -> str:
    """Written when a cluster's training has finished (early stop, max_epochs or an empty cluster)."""
    return f"{MODEL_DIR}/cluster_{cluster}/result.json"


@dataclass(frozen=True)
class Step:
    """One pipeline step: a Snakemake rule and the DVC stage that runs its jobs."""

    stage: str
    rule: str
    smk: str
    script: str
    modules: tuple[str, ...]
    keys: tuple[str, ...]
    deps: tuple[str, ...]
    outs: tuple[str, ...]
    targets: Callable[[dict[str, Any]], list[str]]
    metrics: tuple[str, ...] = ()

    @property
    def code(self) -> list[str]:
        """Files whose change must rerun the step: its rule file, stage script and library modules."""
        return [f"workflow/rules/{self.smk}", self.script, *(f"src/refinenet/{m}.py" for m in self.modules)]


_CLOUD_MODULES = ("sources", "shapes", "meshes", "io", "noise", "atomic", "errors", "stage")
_STAGE_MODULES = ("io", "atomic", "errors", "stage")
MFPS_MODULES = ("mfps", "grid_knn", "neighbors", "noise")
_FEATURE_MODULES = ("features", "filtering", "frames", "heightmaps", "grid_knn", "neighbors", "noise")
_NETWORK_MODULES = (*_FEATURE_MODULES, "clustering", "dataset", "model", "patches")


@dataclass(frozen=True)
class Table:
    """A results table of the paper: which methods are its rows and which metrics its columns."""

    methods: tuple[str, ...]
    metrics: tuple[str, ...]
    title: str

    def outputs(self, name: str) -> tuple[str, ...]:
        return (f"reports/{name}.csv", f"reports/{name}.tex", f"reports/per_cloud/{name}.csv")

    def metrics_file(self, name: str) -> str:
        return f"reports/metrics/{name}.json"


#: Normal estimators and the params blocks that configure each (their values are named in table captions).
METHODS = {"pca": ("baselines",), "jet": ("baselines",), "mfps": ("mfps",), "simple_mfps": ("mfps",),
           REFINENET: ("mfps", "features", "clustering", "network", "patches", "training")}
_SYNTHETIC = ("pca", "jet", "mfps", "simple_mfps", REFINENET)
TABLES = {
    "table_baselines": Table(BASELINES, ("mean", "rmse"), "Baselines: unoriented angular error (degrees)"),
    "table_synthetic": Table(_SYNTHETIC, ("mean", "rmse"), "Synthetic benchmark: unoriented angular error (degrees)"),
    "table_synthetic_pgp": Table(_SYNTHETIC, ("pgp5", "pgp10"),
                                 "Synthetic benchmark: proportion of good points (error below 5 and 10 degrees)"),
}


def _normals_step(stage: str, rule: str, smk: str, script: str, modules: tuple[str, ...], keys: tuple[str, ...],
                  methods: tuple[str, ...], splits: tuple[str, ...] = ("test",)) -> Step:
    """A step estimating normals of every cloud of `splits` with each of `methods`."""
    return Step(
        stage=stage, rule=rule, smk=smk, script=script, modules=(*modules, *_STAGE_MODULES), keys=keys,
        deps=tuple(f"results/clouds/{s}" for s in splits),
        outs=tuple(f"results/normals/{m}/{s}" for m in methods for s in splits),
        targets=lambda p: [normals_path(m, c) for m in methods for s in splits for c in clouds(p, s)],
    )


def _table_step(name: str, table: Table) -> Step:
    blocks = tuple(dict.fromkeys(b for m in table.methods for b in METHODS[m]))
    return Step(
        stage=name, rule="table", smk="tables.smk", script="stages/table.py",
        modules=("tables", "metrics", *_STAGE_MODULES),
        keys=("data.source", "data.path", "data.n_points", "evaluation.protocol", *blocks),
        deps=("results/clouds/test", *(f"results/normals/{m}/test" for m in table.methods)),
        outs=table.outputs(name), metrics=(table.metrics_file(name),),
        targets=lambda p: [*table.outputs(name), table.metrics_file(name)],
    )


STEPS: dict[str, Step] = {s.stage: s for s in (
    *(Step(
        stage=f"{split}_clouds", rule="cloud", smk="data.smk", script="stages/cloud.py", modules=_CLOUD_MODULES,
        keys=("seed", "data", f"noise.{split}"), deps=(), outs=(f"results/clouds/{split}",),
        targets=lambda p, split=split: [cloud_path(c) for c in clouds(p, split)],
    ) for split in ("train", "test")),
    _normals_step("baselines", "baseline_normals", "baselines.smk", "stages/baseline_normals.py",
                  ("baselines", "grid_knn", "neighbors"), ("baselines",), BASELINES),
    _normals_step("mfps", "initial_normals", "initial_normals.smk", "stages/initial_normals.py",
                  MFPS_MODULES, ("mfps", "seed"), ("mfps",), ("train", "test")),
    _normals_step("simple_mfps", "initial_normals", "initial_normals.smk", "stages/initial_normals.py",
                  MFPS_MODULES, ("mfps", "seed"), ("simple_mfps",)),
    Step(
        stage="features", rule="features", smk="features.smk", script="stages/features.py",
        modules=(*_FEATURE_MODULES, *_STAGE_MODULES), keys=("features",),
        deps=("results/clouds/train", "results/clouds/test", "results/normals/mfps/train", "results/normals/mfps/test"),
        outs=("results/features/train", "results/features/test"),
        targets=lambda p: [features_path(c) for c in clouds(p)],
    ),
    Step(
        stage="clusters", rule="clusters", smk="clustering.smk", script="stages/clusters.py",
        modules=(*_FEATURE_MODULES, "clustering", *_STAGE_MODULES), keys=("clustering", "seed"),
        deps=("results/features/train",), outs=("results/clusters",), targets=lambda p: [CLUSTER_MODEL],
    ),
    Step(
        stage="train", rule="train", smk="training.smk", script="stages/train.py",
        modules=(*_NETWORK_MODULES, "training", "metrics", *_STAGE_MODULES),
        keys=("network", "patches", "training", "seed"),
        deps=("results/clouds/train", "results/features/train", "results/clusters"), outs=(MODEL_DIR,),
        targets=lambda p: [trained_marker(c) for c in range(p["clustering"]["n_clusters"])],
    ),
    Step(
        stage="refine", rule="refine", smk="inference.smk", script="stages/refine.py",
        modules=(*_NETWORK_MODULES, "inference", "training", "metrics", *_STAGE_MODULES),
        keys=("network", "patches", "inference", "seed"),
        deps=("results/clouds/test", "results/features/test", "results/clusters", MODEL_DIR),
        outs=(f"results/normals/{REFINENET}/test",),
        targets=lambda p: [normals_path(REFINENET, c) for c in clouds(p, "test")],
    ),
    *(_table_step(name, table) for name, table in TABLES.items()),
    Step(
        stage="metrics", rule="metrics", smk="tables.smk", script="stages/merge_metrics.py",
        modules=("atomic", "errors", "stage"), keys=(), deps=tuple(t.metrics_file(n) for n, t in TABLES.items()),
        outs=(), metrics=("reports/metrics.json",), targets=lambda p: ["reports/metrics.json"],
    ),
)}


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
            "cmd": f"python -m refinenet.bridge run {step.stage}",
            "deps": [*step.code, *step.deps],
            "params": tracked_keys(raw, step),
            "outs": [{o: {"cache": False}} if o.startswith("reports/") else o for o in step.outs],
        }
        if step.metrics:
            stage["metrics"] = [{m: {"cache": False}} for m in step.metrics]
        stages[step.stage] = stage
    return {"stages": stages}


def render_dvc_yaml(raw: dict[str, Any]) -> str:
    header = "# Generated by `python -m refinenet.workflow` from src/refinenet/workflow.py; do not edit by hand.\n"
    return header + yaml.safe_dump(dvc_yaml(raw), sort_keys=False, width=120)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Write dvc.yaml from the pipeline's step declarations.")
    parser.add_argument("--params", default="params.yaml")
    parser.add_argument("--check", action="store_true", help="exit 1 if dvc.yaml is out of date")
    args = parser.parse_args(argv)
    text = render_dvc_yaml(yaml.safe_load(Path(args.params).read_text()))
    if args.check:
        current = DVC_FILE.read_text() if DVC_FILE.exists() else ""
        if current != text:
            print("dvc.yaml is out of date: run `python -m refinenet.workflow`", file=sys.stderr)
            return 1
        return 0
    DVC_FILE.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
